// Compact bright sources of a set of radiance samples (a sun, a lamp a few
// samples wide) taken out as SG lobes of their own energy, centre and
// spread, before the rest is fitted (render/sg FitSg). The fit weighs each
// sample's relative error, so a source one or two samples wide is a few
// samples among thousands: its energy, which the irradiance and the shadows
// are made of, is left to where the lobes happen to settle. Directions
// unit, world frame; radiance linear RGB; solid angles in sr.
#pragma once

#include "render/sg/sg.h"
#include "render/sg/sphere.h"

namespace nerfar {

// The sharpness from which N even samples no longer carry a lobe: an SG is
// a Gaussian of angular width σ = 1/√λ, and N samples lie h = √(4π/N)
// apart. Narrower than one spacing (σ < h, λ > N/(4π): 81 at 1024 ray
// directions, 652 at a 128 × 64 panorama) a source lies on one to four
// samples: a Fibonacci set's sum integrates it to within 1-1.5 % at σ = h
// but 6-11 % at h/2 and 36-44 % at h/2.8 (worst over axes, N = 512..4096),
// and in a fit whose loss weighs each sample's
// relative error those few samples weigh nothing against the N others: a
// 5° sun on a 128 × 64 panorama (σ ≈ 0.7 h) kept 82 % of its flux in a
// 32-lobe fit, a 2° one 4 %.
double CompactSharpness(int samples);

struct CompactSplit {
  SgMixture lobes;       // one per compact source, most energetic first
  RadianceSamples rest;  // the samples with each source replaced by its surroundings' radiance
};

// Sources: clusters of neighbouring samples (within twice the mean spacing
// √(4π/N) of each other) brighter than `hdr_floor` × the samples' mean
// luminance (the fit's own threshold of a light, SgFitOptions::hdr_floor),
// whose spread the samples do not resolve: a lobe of equal second moment
// is sharper than CompactSharpness(N).
// Each lobe: the energy Σ (L_i − L_around)·ω_i above the radiance around
// the cluster (the mean of the dimmer samples next to it), its centroid, and
// λ = 2/E[θ²] with each sample's own cell (ω/6) in the second moment, at
// most 1e4; amplitude energy / ∫ of the unit lobe. At most `max_sources`,
// the most energetic. Samples of unequal solid angle are fine (panorama
// pixels).
CompactSplit SplitCompactSources(const RadianceSamples& samples, int max_sources, double hdr_floor);

}  // namespace nerfar

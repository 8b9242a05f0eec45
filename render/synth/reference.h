// Exact references for testing the synthetic renderer (and anything that
// estimates light from synthetic scenes). Irradiance E is defined so that a
// Lambertian surface of albedo a has radiance a E / pi; units are those of the
// lights (image units). Points and normals in world coordinates, metres.
#pragma once

#include <vector>

#include "calib/core/image.h"
#include "calib/core/math.h"
#include "render/synth/scene.h"

namespace nerfar::synth {

// Irradiance from one unit-amplitude SG lobe exp(lambda (w.p - 1)) on a
// surface whose normal makes cos_angle = n.p with the lobe axis, nothing in
// the way: the clamped-cosine convolution
//   E = integral over the sphere of exp(lambda (w.p - 1)) max(0, n.w) dw.
// Evaluated as a 1-D integral over the polar angle around p (the azimuthal
// part in closed form), split where the clamp starts or stops acting, each
// piece by 128-point Gauss-Legendre after the substitution that makes the
// exponential uniform: relative error below 1e-7 for lambda in [1e-4, 1e4]
// (checked against brute-force quadrature in the tests).
double SgLobeIrradiance(double sharpness, double cos_angle);

// Sum over the lobes (amplitudes per channel).
Vec3 SgIrradiance(const std::vector<EnvLobe>& lobes, const Vec3& normal);

// Irradiance from a uniform sphere emitter entirely above the tangent plane
// of the point (checked): pi L (r / d)^2 cos(theta), exact for a sphere.
Vec3 SphereLightIrradiance(const SphereLight& light, const Vec3& point, const Vec3& normal);

// Irradiance from a uniform rectangle emitter entirely above the tangent
// plane (checked), by Lambert's closed form for polygons:
//   E = L/2 * sum_i angle(v_i, v_i+1) * n . unit(v_i x v_i+1).
// 0 when the point is behind a one-sided emitter.
Vec3 RectangleLightIrradiance(const RectangleLight& light, const Vec3& point, const Vec3& normal);

// The probe seen from `point` with nothing in the scene but the lights: per
// pixel, the mean over supersample^2 regular sub-directions of the radiance of
// the nearest emitter hit (sphere, rectangle front, box) or else the
// environment. Intersections in double precision, independent of Scene's
// ray tracer.
ImageF ReferenceProbe(const Scene& lights, const Vec3& point, int width, int height, int supersample);

}  // namespace nerfar::synth

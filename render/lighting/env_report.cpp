// The environment report (env_report.h): the evaluation's irradiance error,
// the samples each view sees, and the picture's composition.
#include "render/lighting/env_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <limits>
#include <numeric>

#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/media.h"
#include "calib/core/metrics.h"
#include "render/lighting/env_report_draw.h"
#include "render/sg/sphere.h"

namespace nerfar {

using env_report_internal::DrawDot;
using env_report_internal::DrawLobes;
using env_report_internal::DrawPanoramaGuides;
using env_report_internal::GreyBackdrop;
using env_report_internal::HemisphereDots;
using env_report_internal::LobeEnergy;
using env_report_internal::LobeHalfMaxAngle;
using env_report_internal::LobesByEnergy;
using env_report_internal::Paste;
using env_report_internal::ResidualLegend;
using env_report_internal::Resized;

std::vector<Vec3> EvaluationNormals(bool upper_only) {
  constexpr int kNormals = 64;
  std::vector<Vec3> normals;
  for (int i = 0; i < kNormals; ++i) {
    const double t = i + 0.5;
    const double z = 1.0 - 2.0 * t / kNormals, r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = kPi * (1.0 + std::sqrt(5.0)) * t;
    if (!upper_only || z > 0) normals.push_back({r * std::cos(phi), r * std::sin(phi), z});
  }
  return normals;
}

double IrradianceError(const ImageF& estimate, const ImageF& truth, bool upper_only) {
  NERFAR_CHECK(estimate.channels >= 3 && truth.channels >= 3);
  std::vector<Vec3> e_estimate, e_truth;
  for (const Vec3& n : EvaluationNormals(upper_only)) {
    e_estimate.push_back(PanoramaIrradiance(estimate, n));
    e_truth.push_back(PanoramaIrradiance(truth, n));
  }
  return RelativeIrradianceRms(e_estimate, e_truth);
}

double ResidualLog2(const Vec3f& model, const Vec3f& observed) {
  const double m = LuminanceOf(Vec3(model)), o = LuminanceOf(Vec3(observed));
  if (m > 0 && o > 0) return std::log2(m / o);
  if (m > 0) return std::numeric_limits<double>::infinity();
  return o > 0 ? -std::numeric_limits<double>::infinity() : 0.0;
}

std::vector<SampleInView> SamplesSeenInView(const CameraIntrinsics& camera, const Pose& T_world_camera,
                                            const ImageF& surface_depth, const std::vector<Vec3f>& positions,
                                            double depth_tolerance_m) {
  NERFAR_CHECK(surface_depth.width == camera.width && surface_depth.height == camera.height);
  const Pose T_camera_world = T_world_camera.Inverse();
  std::vector<SampleInView> seen;
  for (size_t i = 0; i < positions.size(); ++i) {
    const Vec3 p_camera = T_camera_world * Vec3(positions[i]);
    Vec2 pixel;
    if (!Project(camera, p_camera, pixel)) continue;
    if (!(pixel.x >= 0 && pixel.y >= 0 && pixel.x < camera.width && pixel.y < camera.height)) continue;
    const float depth = surface_depth.at(static_cast<int>(pixel.x), static_cast<int>(pixel.y));
    if (depth > 0 && std::fabs(p_camera.z - depth) <= depth_tolerance_m) seen.push_back({i, pixel});
  }
  return seen;
}

ImageF ReadTruePanorama(const std::string& path) {
  const ImageF image = ReadExrRgb(path);  // InputError naming the file if missing or not an EXR
  if (image.width != 2 * image.height)
    ThrowInputError(path, "is " + std::to_string(image.width) + "x" + std::to_string(image.height) +
                              " (expected an equirect panorama, width = 2 x height)");
  for (size_t p = 0; p < image.PixelCount(); ++p)
    for (int c = 0; c < 3; ++c)
      if (!(image.pixels[p * 3 + c] >= 0))
        ThrowInputError(path, "pixel (" + std::to_string(p % image.width) + ", " + std::to_string(p / image.width) +
                                  ") is negative (expected radiance >= 0)");
  return image;
}

namespace {

// Samples nearer than this many voxels to a view's surface depth count as
// seen: a sample is the median of its own ray's opacity and the view's depth
// the median of the view ray's, on the same surface of the same grid (within
// a voxel or two on a sharp surface; a trained table's fog spreads more);
// a nearer occluder is many voxels off.
constexpr double kSeenDepthVoxels = 4;
// Views are drawn behind the samples as a dimmed grey picture, so that the
// colour of the dots alone carries meaning.
constexpr double kBackdropGain = 0.6;
constexpr int kGutter = 8, kCaption = 18, kTitle = 26, kLineHeight = 16, kLabelledLobes = 5;

std::string Format(const char* format, double a, double b = 0, double c = 0, double d = 0) {
  char buffer[256];
  std::snprintf(buffer, sizeof buffer, format, a, b, c, d);
  return buffer;
}

// The q-quantile (nearest rank) of the values; NaN for none.
double Quantile(std::vector<double> values, double q) {
  if (values.empty()) return std::nan("");
  const size_t k = std::min(values.size() - 1, static_cast<size_t>(q * values.size()));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

// Where a panorama's key light is: the mean direction of its pixels at least
// half as bright as the brightest, weighted by luminance times solid angle
// (zero for a black panorama).
Vec3 KeyLightDirection(const ImageF& panorama) {
  float brightest = 0;
  for (size_t p = 0; p < panorama.PixelCount(); ++p)
    brightest = std::max(brightest, Luminance(&panorama.pixels[p * 3], 3));
  Vec3 sum;
  for (int j = 0; j < panorama.height; ++j)
    for (int i = 0; i < panorama.width; ++i) {
      const float y = Luminance(panorama.Pixel(i, j), 3);
      if (brightest > 0 && y >= 0.5f * brightest)
        sum += EquirectDirection((i + 0.5) / panorama.width, (j + 0.5) / panorama.height) *
               (y * EquirectPixelSolidAngle(panorama.width, panorama.height, j));
    }
  return Length(sum) > 0 ? Normalized(sum) : Vec3{};
}

double AzimuthDeg(const Vec3& d) { return std::atan2(d.y, d.x) * 180 / kPi; }
double ElevationDeg(const Vec3& d) { return std::asin(std::clamp(d.z / Length(d), -1.0, 1.0)) * 180 / kPi; }

// `count` kept views spread around the volume: for each of `count` azimuths
// (from world +x, evenly spaced, half a step off the axes) at the kept views'
// median elevation, the kept view looking from nearest to it, each view once.
// Extremes (grazing views that show mostly sky) are left out unless nothing else is kept.
std::vector<size_t> SpreadViews(const EnvViewReport& views, int count) {
  std::vector<size_t> kept, chosen;
  for (size_t v = 0; v < views.poses.size() && v < views.kept.size(); ++v)
    if (views.kept[v]) kept.push_back(v);
  const auto from = [&](size_t v) { return -(views.poses[v].rotation * Vec3{0, 0, 1}); };
  std::vector<double> elevations;
  for (size_t v : kept) elevations.push_back(ElevationDeg(from(v)));
  const double elevation = Quantile(elevations, 0.5) * kPi / 180;
  for (int k = 0; k < count && !kept.empty(); ++k) {
    const double azimuth = 2 * kPi * (k + 0.5) / count - kPi;
    const Vec3 target{std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth),
                      std::sin(elevation)};
    size_t best = 0;
    for (size_t i = 1; i < kept.size(); ++i)
      if (Dot(from(kept[i]), target) > Dot(from(kept[best]), target)) best = i;
    chosen.push_back(kept[best]);
    kept.erase(kept.begin() + static_cast<std::ptrdiff_t>(best));
  }
  return chosen;
}

// One residual view: the NeRF rendering (dimmed grey) at the tile's size and
// every sample it sees as a dot coloured by log2(model / observed), the
// largest residuals on top.
Image8 ResidualView(const NerfField& field, const EnvEstimateReport& estimate, const Pose& pose,
                    const CameraIntrinsics& tile_camera, const EnvReportOptions& options, std::string* caption) {
  const CameraIntrinsics render_camera =
      tile_camera.Scaled(options.view_render_width,
                         std::max(1, static_cast<int>(std::lround(static_cast<double>(options.view_render_width) *
                                                                  tile_camera.height / tile_camera.width))));
  const NerfImages view = RenderView(field, render_camera, pose, options.render);
  const Image8 grey = ToGray(ToneMapToDisplay(view.color, ExposureForPercentile(view.color)));
  Image8 tile = GreyBackdrop(Resized(grey, tile_camera.width, tile_camera.height, false), kBackdropGain);
  const EnvSurfaceSamples& s = estimate.surface;
  std::vector<SampleInView> seen =
      SamplesSeenInView(render_camera, pose, view.surface_depth, s.positions, kSeenDepthVoxels * field.voxel_m);
  std::vector<double> residual(seen.size());
  for (size_t k = 0; k < seen.size(); ++k)
    residual[k] = ResidualLog2(estimate.fit.modelled[seen[k].sample], s.radiance[seen[k].sample]);
  std::vector<size_t> order(seen.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return std::fabs(residual[a]) < std::fabs(residual[b]); });
  const double scale = static_cast<double>(tile_camera.width) / render_camera.width;
  // Dots of half the radius of the disk each sample would own if those seen
  // covered half the tile (they do not overlap much), from 1.5 px (still a
  // colour) to 3 px (few samples).
  const double radius =
      std::clamp(std::sqrt(0.5 * tile.width * tile.height / (kPi * std::max<size_t>(seen.size(), 1))) / 2, 1.5, 3.0);
  for (size_t k : order)
    DrawDot(tile, {seen[k].pixel.x * scale, seen[k].pixel.y * scale}, radius,
            DivergingColour(residual[k] / kResidualScaleLog2));
  const Vec3 from = -(pose.rotation * Vec3{0, 0, 1});
  *caption = Format("residual, view from azimuth %.0f elevation %.0f: ", AzimuthDeg(from), ElevationDeg(from)) +
             std::to_string(seen.size()) + " samples";
  if (!residual.empty()) *caption += Format(", median x%.2f", std::exp2(Quantile(residual, 0.5)));
  return tile;
}

// The share (in %) of the values for which `test` holds; 0 for none.
template <typename Test>
double PercentWhere(const std::vector<double>& values, Test test) {
  return values.empty() ? 0.0 : 100.0 * std::count_if(values.begin(), values.end(), test) / values.size();
}

// The fit's residual (relative RMS, robust loss, with and without
// environment; model / observed over the samples), its model selection, and
// how much of the samples' light the environment gives.
std::vector<std::string> FitLines(const EnvLight& env, const EnvEstimateReport& estimate) {
  const EnvFitResidual& fit = env.fit;
  std::vector<std::string> lines;
  std::string residual = "fit over " + std::to_string(fit.samples) + " surface samples: relative RMS " +
                         Format("%.3f", fit.relative_rms) + ", robust loss " + Format("%.4f", fit.loss);
  if (fit.near_only_fitted)
    residual += Format("; near field only: relative RMS %.3f, robust loss %.4f", fit.near_only_relative_rms,
                       fit.near_only_loss);
  lines.push_back(residual);
  const EnvSurfaceSamples& s = estimate.surface;
  std::vector<double> log2_ratio;
  for (size_t i = 0; i < s.size(); ++i) {
    const double r = ResidualLog2(estimate.fit.modelled[i], s.radiance[i]);
    if (std::isfinite(r)) log2_ratio.push_back(r);
  }
  lines.push_back(Format("model / observed over the samples: median x%.2f, quartiles x%.2f .. x%.2f; ",
                         std::exp2(Quantile(log2_ratio, 0.5)), std::exp2(Quantile(log2_ratio, 0.25)),
                         std::exp2(Quantile(log2_ratio, 0.75))) +
                  Format("%.0f %% within a factor of 1.41",
                         PercentWhere(log2_ratio, [](double r) { return std::fabs(r) <= 0.5; })));
  if (env.evidence_needed > 0)
    lines.push_back(Format("model selection: the environment's log-likelihood gain %.1f against the BIC penalty %.1f",
                           env.evidence, env.evidence_needed) +
                    (env.evidence > env.evidence_needed ? ": supported" : ": not supported"));
  lines.push_back(Format("environment / near-field irradiance: %.3f over the samples, %.3f at the volume centre",
                         env.env_to_near_surface, env.env_to_near_center) +
                  (env.negligible ? "; NEGLIGIBLE: insertion drops the environment" : "; kept"));
  if (estimate.e_env.size() == s.size() && s.e_nerf.size() == s.size()) {
    std::vector<double> share;  // of the environment in each sample's modelled irradiance g·E_nerf + E_env
    for (size_t i = 0; i < s.size(); ++i) {
      const double e_env = LuminanceOf(estimate.e_env[i]),
                   e_all = e_env + estimate.fit.near_field_gain * LuminanceOf(Vec3(s.e_nerf[i]));
      if (e_all > 0) share.push_back(e_env / e_all);
    }
    lines.push_back(
        Format("the environment's share of each sample's irradiance: median %.0f %%, quartiles %.0f .. %.0f %%",
               100 * Quantile(share, 0.5), 100 * Quantile(share, 0.25), 100 * Quantile(share, 0.75)) +
        Format("; lit mostly by it: %.0f %% of the samples", PercentWhere(share, [](double f) { return f > 0.5; })));
  }
  return lines;
}

// The lobes carrying the most energy, as numbered on the panoramas, with
// the distance of a light placed at one (EnvLight::distance_m).
std::vector<std::string> LobeLines(const SgMixture& lobes, const std::vector<double>& distance_m) {
  double total = 0;
  for (const Sg& g : lobes) total += LobeEnergy(g);
  std::vector<std::string> lines = {std::to_string(lobes.size()) +
                                    " lobes; the brightest (numbered on the panoramas):"};
  const std::vector<size_t> order = LobesByEnergy(lobes);
  for (size_t k = 0; k < order.size() && static_cast<int>(k) < kLabelledLobes; ++k) {
    const Sg& g = lobes[order[k]];
    lines.push_back("  " + std::to_string(k + 1) +
                    Format(": azimuth %4.0f, elevation %3.0f deg; sharpness %.3g (half maximum at %.1f deg); ",
                           AzimuthDeg(g.axis), ElevationDeg(g.axis), g.sharpness,
                           LobeHalfMaxAngle(g.sharpness) * 180 / kPi) +
                    Format("%.0f %% of the energy; RGB %.3g %.3g %.3g", total > 0 ? 100 * LobeEnergy(g) / total : 0.0,
                           g.amplitude.x, g.amplitude.y, g.amplitude.z) +
                    (order[k] < distance_m.size() && distance_m[order[k]] > 0
                         ? Format("; %.2f m from the origin", distance_m[order[k]])
                         : std::string()));
  }
  return lines;
}

// The comparison with the truth: the evaluation's irradiance error and the key lights' directions.
std::vector<std::string> TruthLines(const EnvReportLayout& layout) {
  std::vector<std::string> lines;
  lines.push_back(std::isfinite(layout.irradiance_error_upper)
                      ? Format("irradiance error against the truth (luminance, relative RMS; eval/metrics.py "
                               "irradiance): %.4f over the 32 upper normals, %.4f over all 64",
                               layout.irradiance_error_upper, layout.irradiance_error_sphere)
                      : std::string("irradiance error: the truth is black (no light from outside the volume); "
                                    "the estimate should be negligible"));
  if (Length(layout.key_truth) > 0 && Length(layout.key_estimate) > 0)
    lines.push_back(
        Format("key light (pixels at least half the brightest): truth at azimuth %.0f, elevation %.0f deg; ",
               AzimuthDeg(layout.key_truth), ElevationDeg(layout.key_truth)) +
        Format("estimate at azimuth %.0f, elevation %.0f deg: %.1f deg apart", AzimuthDeg(layout.key_estimate),
               ElevationDeg(layout.key_estimate),
               std::acos(std::clamp(Dot(layout.key_truth, layout.key_estimate), -1.0, 1.0)) * 180 / kPi));
  return lines;
}

std::vector<std::string> ReportLines(const EnvLight& env, const EnvEstimateReport& estimate,
                                     const EnvReportLayout& layout, bool with_truth) {
  std::vector<std::string> lines = FitLines(env, estimate);
  for (const std::string& line : LobeLines(env.lobes, env.distance_m)) lines.push_back(line);
  for (const std::string& line : SourceSupportLines(env.lobes, estimate.fit.lobe_support)) lines.push_back(line);
  if (with_truth)
    for (const std::string& line : TruthLines(layout)) lines.push_back(line);
  lines.push_back(Format("panoramas: exposure %.4g (1 / the mean luminance over the sphere of the ", layout.exposure) +
                  (with_truth ? "truth" : "estimate") +
                  "), lines every 30 deg of elevation; lobe circles at half maximum");
  return lines;
}

// Mean luminance over the sphere, each pixel weighted by its solid angle.
double MeanLuminance(const ImageF& panorama) {
  double sum = 0;
  for (int j = 0; j < panorama.height; ++j) {
    double row = 0;
    for (int i = 0; i < panorama.width; ++i) row += Luminance(panorama.Pixel(i, j), 3);
    sum += row * EquirectPixelSolidAngle(panorama.width, panorama.height, j);
  }
  return sum / (4 * kPi);
}

// The panoramas' exposure: the mean radiance over the sphere shows at the
// middle of the tone curve (x/(1+x) = 1/2). The mean, unlike a percentile of
// the pixels, weighs each direction by its solid angle, whatever the equirect
// stretching: sources near a pole fill many more pixels than their solid
// angle, so a percentile can land on a source and show everything else
// black. The truth's when it holds light, else the estimate's.
float PanoramaExposure(const ImageF& estimate, const ImageF* truth) {
  const double mean = truth != nullptr && MeanLuminance(*truth) > 0 ? MeanLuminance(*truth) : MeanLuminance(estimate);
  return mean > 0 ? static_cast<float>(1.0 / mean) : 1.0f;
}

// Signed luminance difference estimate − truth per pixel of the truth's grid,
// coloured with ±1/exposure (the truth's mean luminance) at the scale's ends.
Image8 DifferencePicture(const ImageF& estimate, const ImageF& truth, float exposure) {
  NERFAR_CHECK(estimate.width == truth.width && estimate.height == truth.height);
  Image8 picture(truth.width, truth.height, 3);
  for (size_t p = 0; p < truth.PixelCount(); ++p) {
    const double d = LuminanceOf(Vec3(estimate.pixels[p * 3], estimate.pixels[p * 3 + 1], estimate.pixels[p * 3 + 2])) -
                     LuminanceOf(Vec3(truth.pixels[p * 3], truth.pixels[p * 3 + 1], truth.pixels[p * 3 + 2]));
    const auto c = DivergingColour(d * exposure);
    std::copy(c.begin(), c.end(), picture.pixels.begin() + static_cast<std::ptrdiff_t>(p * 3));
  }
  return picture;
}

// log2(E_estimate / E_truth) of luminance irradiance at each upper normal.
std::vector<double> IrradianceRatios(const ImageF& estimate, const ImageF& truth, const std::vector<Vec3>& normals) {
  std::vector<double> ratios;
  for (const Vec3& n : normals) {
    const double e = LuminanceOf(PanoramaIrradiance(estimate, n)), t = LuminanceOf(PanoramaIrradiance(truth, n));
    ratios.push_back(e > 0 && t > 0 ? std::log2(e / t) : (e > t ? 1e9 : (e < t ? -1e9 : 0.0)));
  }
  return ratios;
}

// A picture and its caption at a place on the page.
struct Piece {
  Image8 image;
  std::string caption;
  PictureRect rect;
};

Image8 Placeholder(int width, int height, const std::string& text) {
  Image8 panel(width, height, 3, 36);
  DrawText(panel, text, 12, height / 2 - 6, 1.0);
  return panel;
}

// The panoramas (estimate, truth, difference) and the irradiance plot, placed from `top`; returns the y below them.
int PlacePanoramas(const EnvLight& env, const ImageF* truth, const EnvReportOptions& options, int top,
                   EnvReportLayout& layout, std::vector<Piece>& pieces) {
  const int pw = options.panorama_width, ph = pw / 2;
  const ImageF estimate = RenderEquirect(env.lobes, pw, ph);
  layout.exposure = PanoramaExposure(estimate, truth);
  Image8 estimate_picture = ToneMapToDisplay(estimate, layout.exposure);
  DrawPanoramaGuides(estimate_picture);
  DrawLobes(estimate_picture, env.lobes, kLabelledLobes, false);
  const int left = kGutter, right = 2 * kGutter + pw, row = top + kCaption;
  layout.estimate = {left, row, pw, ph};
  pieces.push_back({estimate_picture,
                    "estimate: " + std::to_string(env.lobes.size()) + " lobes, the 5 brightest numbered; exposure " +
                        Format("%.3g", layout.exposure),
                    layout.estimate});
  layout.truth = {right, row, pw, ph};
  if (truth == nullptr) {
    pieces.push_back({Placeholder(pw, ph, "no truth given (--truth env.exr compares)"), "truth", layout.truth});
    return row + ph + kGutter;
  }
  const ImageF estimate_on_truth_grid = RenderEquirect(env.lobes, truth->width, truth->height);
  layout.irradiance_error_upper = IrradianceError(estimate_on_truth_grid, *truth, true);
  layout.irradiance_error_sphere = IrradianceError(estimate_on_truth_grid, *truth, false);
  layout.key_truth = KeyLightDirection(*truth);
  layout.key_estimate = KeyLightDirection(estimate_on_truth_grid);
  Image8 truth_picture = Resized(ToneMapToDisplay(*truth, layout.exposure), pw, ph, true);
  DrawPanoramaGuides(truth_picture);
  DrawLobes(truth_picture, env.lobes, kLabelledLobes, true);
  pieces.push_back({truth_picture, "truth, same exposure (the estimate's 5 brightest lobes marked)", layout.truth});
  const int row2 = row + ph + kGutter + kCaption;
  Image8 difference = Resized(DifferencePicture(estimate_on_truth_grid, *truth, layout.exposure), pw, ph, true);
  DrawPanoramaGuides(difference);
  layout.difference = {left, row2, pw, ph};
  pieces.push_back({difference,
                    Format("estimate - truth, luminance: blue -%.3g (missing) .. red +%.3g (extra)",
                           1.0 / layout.exposure, 1.0 / layout.exposure),
                    layout.difference});
  const std::vector<Vec3> normals = EvaluationNormals(true);
  layout.irradiance = {right, row2, ph, ph};
  pieces.push_back(
      {HemisphereDots(ph, normals, IrradianceRatios(estimate_on_truth_grid, *truth, normals), kResidualScaleLog2),
       "irradiance estimate / truth, upper normals", layout.irradiance});
  Image8 numbers(pw - ph - kGutter, ph, 3, 24);
  const std::string lines[] = {"irradiance error",
                               "(relative RMS,",
                               " eval/metrics.py)",
                               Format("upper: %.4f", layout.irradiance_error_upper),
                               Format("all 64: %.4f", layout.irradiance_error_sphere),
                               "",
                               "dots: estimate / truth",
                               "on the scale below",
                               "(blue: too dark)"};
  for (size_t i = 0; i < std::size(lines); ++i) DrawText(numbers, lines[i], 4, 8 + 18 * static_cast<int>(i), 1.1);
  pieces.push_back({numbers, "", {right + ph + kGutter, row2, numbers.width, ph}});
  return row2 + ph + kGutter;
}

// The residual views in two columns from `top`; returns the y below them.
int PlaceViews(const NerfField& field, const EnvEstimateReport& estimate, const EnvReportOptions& options, int top,
               EnvReportLayout& layout, std::vector<Piece>& pieces, const EnvProgress& progress) {
  const std::vector<size_t> chosen = SpreadViews(estimate.views, options.views);
  const CameraIntrinsics& sampled = estimate.views.camera;
  int y = top;
  for (size_t k = 0; k < chosen.size(); ++k) {
    if (progress) progress("report", k, chosen.size());
    const CameraIntrinsics camera = sampled.Scaled(
        options.view_width,
        static_cast<int>(std::lround(static_cast<double>(options.view_width) * sampled.height / sampled.width)));
    const Pose& pose = estimate.views.poses[chosen[k]];
    std::string caption;
    Image8 tile = ResidualView(field, estimate, pose, camera, options, &caption);
    const int column = static_cast<int>(k % 2);
    y = top + static_cast<int>(k / 2) * (kCaption + camera.height + kGutter);
    const PictureRect rect{kGutter + column * (options.view_width + kGutter), y + kCaption, camera.width,
                           camera.height};
    layout.views.push_back(rect);
    layout.view_cameras.push_back(camera);
    layout.view_poses.push_back(pose);
    pieces.push_back({std::move(tile), caption, rect});
  }
  if (progress) progress("report", chosen.size(), chosen.size());
  return layout.views.empty() ? top : layout.views.back().y + layout.views.back().height + kGutter;
}

}  // namespace

std::vector<std::string> SourceSupportLines(const SgMixture& lobes, const std::vector<SourceSupport>& support) {
  std::vector<std::string> lines;
  for (size_t k = 0; k < lobes.size() && k < support.size(); ++k) {
    if (!(support[k].half_share > 0)) continue;
    const SourceSupport& s = support[k];
    lines.push_back(
        Format("sharp source at azimuth %.0f, elevation %.0f deg: half its gain from %.1f %% of the samples",
               AzimuthDeg(lobes[k].axis), ElevationDeg(lobes[k].axis), 100 * s.half_share) +
        Format(", within %.2f m of (%.2f, %.2f", s.radius_m, s.centre.x, s.centre.y) + Format(", %.2f)", s.centre.z));
  }
  return lines;
}

Image8 RenderEnvReport(const NerfField& field, const EnvLight& env, const EnvEstimateReport& estimate,
                       const ImageF* truth, const EnvReportOptions& options, EnvReportLayout* layout_out,
                       const EnvProgress& progress) {
  NERFAR_CHECK_EQ(estimate.fit.modelled.size(), estimate.surface.size());
  NERFAR_CHECK_EQ(estimate.views.poses.size(), estimate.views.kept.size());
  NERFAR_CHECK(options.panorama_width >= 64 && options.view_width <= options.panorama_width);
  EnvReportLayout layout;
  std::vector<Piece> pieces;
  const int page_width = 2 * options.panorama_width + 3 * kGutter;
  int y = PlacePanoramas(env, truth, options, kTitle, layout, pieces);
  y = PlaceViews(field, estimate, options, y, layout, pieces, progress);
  const Image8 legend = ResidualLegend(page_width - 2 * kGutter, kResidualScaleLog2,
                                       "model / observed: too dark, light missing there", "too bright");
  pieces.push_back({legend, "", {kGutter, y, legend.width, legend.height}});
  y += legend.height + kGutter;
  layout.lines = ReportLines(env, estimate, layout, truth != nullptr);

  Image8 page(page_width, y + kLineHeight * static_cast<int>(layout.lines.size()) + kGutter, 3, 24);
  DrawText(page, "nerfar env report: " + (env.source.empty() ? std::string("estimate") : env.source), kGutter, 6, 1.3);
  for (const Piece& piece : pieces) {
    Paste(page, piece.image, piece.rect.x, piece.rect.y);
    if (!piece.caption.empty()) DrawText(page, piece.caption, piece.rect.x, piece.rect.y - kCaption + 3, 1.0);
  }
  for (size_t i = 0; i < layout.lines.size(); ++i)
    DrawText(page, layout.lines[i], kGutter, y + kLineHeight * static_cast<int>(i), 1.0);
  if (layout_out) *layout_out = std::move(layout);
  return page;
}

}  // namespace nerfar

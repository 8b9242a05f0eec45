// What an environment estimate is worth, shown to people: `nerfar env`'s
// report picture and the numbers in it. The estimate's panorama (the scenes'
// equirect convention, render/sg/sphere.h: +z at the top row, +x at the
// centre, +y at u = 1/4), tone mapped at a stated exposure, with the lobes
// marked (axis, and a circle at the half-maximum angle acos(1 − ln2/λ)); the
// fit's residual log2(model / observed) over the surface samples, drawn where
// they project in a few of the sampled views' NeRF renderings; with a true
// panorama, the truth beside the estimate at the same exposure, their
// difference and the irradiance error of shared/eval/metrics.py `irradiance`.
// World frame, metres, linear RGB radiance; pictures are 8-bit sRGB.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/image.h"
#include "render/lighting/env_estimate.h"
#include "render/lighting/env_light.h"
#include "render/nerf/nerf_field.h"

namespace nerfar {

// --- The evaluation's irradiance error (shared/eval/metrics.py `irradiance [--upper]`)

// metrics.py's 64 normals (fib_dirs: z = 1 − (2i + 1)/64, azimuth
// π(1 + √5)(i + ½); not FibonacciSphere's, which turns the other way), those
// with z > 0 when upper_only (32).
std::vector<Vec3> EvaluationNormals(bool upper_only);
// Relative RMS over those normals of the luminance irradiance of `estimate`
// against `truth`, each panorama (3 channels, any size) integrated over its
// pixels' solid angles: sqrt(Σ (E − E_true)²) / sqrt(Σ E_true²); +∞ when the
// truth is black and the estimate is not, 0 when both are.
double IrradianceError(const ImageF& estimate, const ImageF& truth, bool upper_only);

// --- The residual over the surface samples

// log2(model / observed) of luminance: negative where the model is too dark
// (light is missing there), positive where it is too bright. ±∞ where one of
// them is 0 and the other is not, 0 where both are.
double ResidualLog2(const Vec3f& model, const Vec3f& observed);

// The report's diverging colour scale: t = −1 blue, 0 near-white, +1 red
// (ColorBrewer RdBu), clamped to [−1, 1]; sRGB.
std::array<std::uint8_t, 3> DivergingColour(double t);
// Residuals are coloured by t = log2(model / observed) / kResidualScaleLog2:
// the scale ends at a factor of 2 either way.
inline constexpr double kResidualScaleLog2 = 1.0;

// A sample seen in a view: its index and continuous pixel coordinates
// (calib/camera.h convention: pixel centres at i + 0.5).
struct SampleInView {
  size_t sample = 0;
  Vec2 pixel;
};
// The samples that a view sees: in front of the camera, inside the image and
// within `depth_tolerance_m` of the view's surface depth (along the viewing
// axis, 1 channel, the camera's size) at their pixel; samples behind a nearer
// surface are left out.
std::vector<SampleInView> SamplesSeenInView(const CameraIntrinsics& camera, const Pose& T_world_camera,
                                            const ImageF& surface_depth, const std::vector<Vec3f>& positions,
                                            double depth_tolerance_m);

// --- The picture

struct EnvReportOptions {
  int views = 4;                // sampled views shown (at as many azimuths around the scene)
  int view_width = 512;         // each view's tile (its height from the sampled views' aspect)
  int view_render_width = 256;  // the NeRF rendering behind it, upsampled to the tile (rays cost time)
  int panorama_width = 512;     // each panorama's width (height: half)
  NerfRenderOptions render;     // the NeRF renderings' settings (the estimate's own)
};

struct PictureRect {
  int x = 0, y = 0, width = 0, height = 0;  // top-left corner and size, pixels; width 0: absent
};

// Where each part of the picture lies, and the numbers it states.
struct EnvReportLayout {
  // The panoramas (2:1) and the irradiance plot; without truth the truth's
  // place holds a note, and the last two are absent.
  PictureRect estimate, truth, difference, irradiance;
  std::vector<PictureRect> views;              // the residual views
  std::vector<CameraIntrinsics> view_cameras;  // per view: the camera of its tile
  std::vector<Pose> view_poses;                // per view: T_world_camera
  float exposure = 1;  // of both panoramas: 1 / mean luminance over the sphere of the truth (else of the estimate)
  double irradiance_error_upper = 0, irradiance_error_sphere = 0;  // with truth (metrics.py irradiance [--upper])
  // With truth: the key light's direction in each (the mean direction of the
  // pixels at least half as bright as the brightest; zero when black).
  Vec3 key_truth, key_estimate;
  std::vector<std::string> lines;  // the text block
};

// The report picture of an estimate. `estimate` must hold the samples
// (EnvEstimateReport::keep_samples), their modelled radiance and the views;
// `truth` (3 channels) may be null. Progress stage "report".
Image8 RenderEnvReport(const NerfField& field, const EnvLight& env, const EnvEstimateReport& estimate,
                       const ImageF* truth, const EnvReportOptions& options, EnvReportLayout* layout = nullptr,
                       const EnvProgress& progress = nullptr);

// One line per sharp source of `lobes` (EnvFitReport::lobe_support, per
// lobe): where its evidence lies, "sharp source at azimuth A, elevation E
// deg: half its gain from P % of the samples, within R m of (x, y, z)". The
// report picture shows them and `nerfar env` logs them.
std::vector<std::string> SourceSupportLines(const SgMixture& lobes, const std::vector<SourceSupport>& support);

// A true panorama for the report: 3 channels, width = 2 × height, finite and
// non-negative; InputError "path: what is wrong (expected ...)" otherwise.
ImageF ReadTruePanorama(const std::string& path);

}  // namespace nerfar

// Training a NerfField from posed linear-HDR images on the CPU.
//
// Coarse to fine: a dense grid of coarse_voxel_m is optimised first, then each
// level halves the voxel, allocating bricks only around occupied cells and
// initialising them by trilinear upsampling. Every step renders a batch of
// random training rays (jittered inside their pixels), compares them with the
// pixels by a relative L2 loss that is right for HDR, back-propagates through
// the volume rendering into the touched vertices, and applies sparse Adam
// with a total-variation prior. Loss per ray and channel:
//   (C - y)² / (sg(C) + ε)²,  ε = loss_epsilon · (99th-percentile luminance)
// For C ≪ ε this is plain L2 scaled like the psnr_tm metric; for bright
// pixels (an emitter, 1e3) it is the relative error, so radiance is right across
// the range and MC noise averages out (the target enters linearly). Pixels
// that are exactly 0 (rays that hit nothing) also pull the ray's opacity to 0.
// A channel an 8-bit sensor clipped is a lower bound (no loss above it), and
// masked pixels are not used.
// Results do not depend on the thread count: rays are drawn by a counter-based
// hash of (seed, step, ray), and gradients are accumulated in a fixed order.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/image.h"
#include "calib/core/math.h"
#include "calib/dataset.h"
#include "render/nerf/nerf_field.h"

namespace nerfar {

// The version of the checkpoints this build writes (nerf_train.cpp has the layout).
inline constexpr uint32_t kNerfCheckpointVersion = 3;

struct NerfView {
  std::string name;        // file name without folder and extension, e.g. "r_003"
  std::string image_path;  // where the image came from ("" for in-memory views)
  CameraIntrinsics camera;
  Pose T_world_camera;  // OpenCV camera convention
  ImageF rgb;           // linear HDR, 3 channels, camera.width x camera.height
  // Per pixel, bit c set where channel c was clipped by the sensor (an 8- or
  // 16-bit frame at its top value): the radiance is at least rgb there, so
  // the loss only pulls the rendering up to it, never down. Empty: none.
  Image8 clipped;
  // Per pixel, 0 where the pixel is not learnt from (a dataset's mask_path).
  // Empty: every pixel.
  Image8 mask;
};

struct NerfTrainData {
  Aabb aabb;
  std::vector<NerfView> train;     // views to fit
  std::vector<NerfView> held_out;  // views to report PSNR on (may be empty)
  std::string source;              // where it was read from (names the checkpoint's data)
};

// Reads DIR/transforms_train.json (or transforms.json) and, when present,
// DIR/transforms_test.json as the held-out views. Images are linear (EXR) or
// display-referred PNG/JPEG linearised as calib/linear_image.h says (DIR's
// camera.json response, else sRGB; logged). Without an aabb the box is
// derived (calib/scene_box.h: DIR/board.json when present, else the cameras)
// and logged.
NerfTrainData ReadNerfTrainData(const std::string& dataset_dir);

struct NerfTrainOptions {
  // Optimisation steps in all (the schedule below is in fractions of them).
  int steps = 3000;
  // Training rays per step; larger batches give smoother gradients at the same cost per ray.
  int rays_per_step = 8192;
  // Voxel side of the first (dense) level, metres.
  double coarse_voxel_m = 0.01;
  // Number of levels; each halves the voxel side (finest = coarse / 2^(levels-1)).
  int levels = 2;
  // Fraction of the steps at which the finest level starts; the levels in between start evenly before it.
  double last_level_start = 0.4;
  // Sample spacing along training and evaluation rays, in voxels of the current level.
  double step_voxels = 0.5;
  // Adam learning rates of the raw log-density and of the log-colour coefficients
  // (the fast preset doubles lr_density: sharper surfaces, see Preset).
  double lr_density = 0.1, lr_color = 0.05;
  // Decoupled weight decay of the colour slopes b (log L = a + b·d), per unit of
  // the colour learning rate: every update multiplies b by (1 - lr_color_now ·
  // color_slope_decay). A surface seen only from a band of directions (cameras
  // ringing a table from above) constrains a + b·d there only; Adam moves a and
  // b by similar amounts, so a colour that had to rise from its start far
  // (emitters, 1e3) rises much less towards directions no camera saw (from
  // below) and the extrapolation falls below every seen value. The decay lets
  // the data keep the slopes they need (Adam's step is up to lr per update,
  // the decay lr · decay · |b|) and returns unconstrained slopes to 0, i.e.
  // unseen directions to the view-independent colour a. 0 switches it off, in
  // every preset: a face seen only at grazing angles (a lamp's panel) shares its
  // voxels with the dark back behind it, and only its slopes tell the two apart;
  // the decay averages them, and the light that face sends the object is lost
  // (docs/history/nerf.md, "The colour-slope decay and the near field").
  double color_slope_decay = 0.0;
  // The learning rates decay exponentially to this factor of their start by the last step.
  double lr_final_factor = 0.05;
  // Total-variation weights (squared differences to the 6 neighbours), per step. The data
  // gradients are means over the batch (~1e-6 per vertex), so a weight of that order
  // competes with the data and smooths detail away; two orders below it keeps detail
  // and still stops floaters, which grow with none at all.
  double tv_density = 1e-8, tv_color = 1e-8;
  // Weight of the opacity penalty O² on rays whose pixel is exactly 0 (nothing hit).
  double background_weight = 0.1;
  // Weight of the penalty (1 - O)² on rays whose pixel and its 4 neighbours are not 0
  // (something opaque was hit; the neighbours keep silhouette pixels out).
  // Without it a surface seen only from one side is ambiguous: opacity O and
  // radiance c/O render the same pixel, and the fit settles on translucent
  // surfaces with brighter colour (tiny test scene: table top O ≈ 0.3), the fog
  // that leaves receivers without opacity and depth without a surface. The fast
  // and accurate presets use 1: at 0.1 surfaces seen only at grazing angles (the
  // far part of a table) stay translucent and their T = 0.5 depth falls behind them.
  double foreground_weight = 0.1;
  // Weight (1/m) of the distortion prior on every ray, Σ_ij w_i w_j |t_i - t_j| + Σ_i w_i² δ_i / 3
  // (w_i = T_i α_i, t in metres): it gathers each ray's weights into one short
  // interval. Off in every preset: it gathers the weights but does not place
  // them (strong enough to shorten the rays' weights, it moves surfaces forward
  // and costs psnr); a higher log-density learning rate sharpens surfaces
  // without that (docs/history/nerf.md, "Preset choices").
  double distortion_weight = 0.0;
  // Weight of the sparsity prior Σ_i α_i on every ray (α_i the opacity of sample i).
  // Its density gradient λ (1 - α) σ δ vanishes on opaque surfaces (α -> 1) and
  // pushes faint fog (α ≪ 1) down where the data barely constrain it (behind
  // surfaces, in thin fog that merely tints), which Adam would otherwise grow at
  // the same rate as the surfaces (it normalises every vertex's step).
  double sparsity_weight = 0.0;
  // ε of the relative loss in units of the training images' 99th-percentile luminance.
  double loss_epsilon = 0.5;
  // Steps between occupancy updates (empty-space skipping for the next steps).
  int occupancy_every = 16;
  // A cell is empty when σ at all its corners is below this (1/m). The same at
  // every level (not scaled with 1/voxel), so surfaces blurred by upsampling are
  // never pruned; 1/m stops under 1 % of the light over 1 cm.
  double occupancy_sigma = 1.0;
  // Training occupancy threshold (1/m) at the finest level once its prune_delay
  // has passed; 0: occupancy_sigma. Above occupancy_sigma it stops the faint fog
  // around surfaces (σ of a few per metre, most of the finest level's occupied
  // cells) from costing samples; a cell next to an occupied one still receives
  // gradients through its shared corners, so surfaces can still grow.
  double occupancy_sigma_finest = 0.0;
  // Occupancy threshold (1/m) of the saved model (FinalField); 0: occupancy_sigma.
  // Cells whose corners all stay below it are empty in the file: the renderer
  // skips them and the file stores none of their vertices. A higher value than
  // the training threshold drops the faint fog training leaves around surfaces
  // (σ of a few per metre), which is most of the finest level's cells.
  double save_occupancy_sigma = 0.0;
  // Steps after each upsampling before the occupancy is refreshed (the new level keeps
  // every cell it was given); the first level prunes from the start.
  int prune_delay = 64;
  // Weight-based pruning: every prune_every steps, each vertex whose largest
  // rendering weight T·α (over the training samples that touched it since the
  // last prune) stayed below prune_weight is emptied (raw density set to
  // kNerfPrunedDensityRaw). This removes the fog no ray sees (behind surfaces,
  // outside every view) and the faint fog in front of surfaces; surfaces give
  // their vertices weights of 0.1..1. 0 switches it off. The window must be
  // long enough for every surface cell to be hit: prune_every x rays_per_step
  // rays ~ 5e5 hit a 5 mm cell of these scenes ~17 times on average.
  double prune_weight = 1e-3;
  // At the finest level only (surfaces are opaque by then), a sample counts for
  // pruning only if its weight is at least this fraction of the largest weight
  // on its ray: faint fog in front of or behind a surface is then emptied even
  // where its absolute weight exceeds prune_weight. 0 switches it off.
  double prune_relative = 0.0;
  int prune_every = 128;
  // Initial density (1/m) of the coarse level: a light fog that lets every voxel receive gradients.
  double initial_sigma = 4.0;
  // Seed of the ray sampler.
  uint64_t seed = 1;
  // Wall-clock budget in seconds (0: none). When set, the schedule follows
  // max(step / steps, elapsed / max_seconds), so training ends in time (no
  // longer bit-reproducible).
  double max_seconds = 0;
  // Held-out views rendered for the periodic PSNR (0: none; all at the end).
  int eval_views = 2;

  // "fast", "balanced", "accurate"; InputError for other names.
  static NerfTrainOptions Preset(const std::string& name);
  // Every problem with the values, "field: what (expected)".
  std::vector<std::string> Validate() const;
  // Compact JSON of every field (logged at start, stored in checkpoints).
  std::string ToJson() const;
  // Sets one field from "key=value" (the CLI's --set); InputError if unknown or bad.
  void Set(const std::string& key_value);
};

// One training ray's loss and gradient, the trainer's inner computation (public
// for the tests, which check it against finite differences).
namespace nerf_train_detail {

// A sample along the ray, in order of t: position t (m), interval δ (m), density σ (1/m), radiance.
struct RaySample {
  float t = 0, dt = 0, sigma = 0;
  Vec3f color;
};

struct RayLossTerms {
  float epsilon = 1;            // ε of the relative colour loss (absolute radiance)
  float gradient_scale = 1;     // factor on every gradient (the trainer's 1 / batch); the loss is unscaled
  float opacity_weight = 0;     // weight of (O - opacity_target)² (0: no opacity term)
  float opacity_target = 0;     // 0: background pixel, 1: opaque foreground pixel
  float distortion_weight = 0;  // NerfTrainOptions::distortion_weight
  float sparsity_weight = 0;    // NerfTrainOptions::sparsity_weight
  // Bit c: target[c] was clipped, a lower bound: no loss while C[c] >= target[c].
  unsigned clipped_channels = 0;
};

// Returns the ray's loss, Σ_ch (C - y)² / (C + ε)² / 3 (for a clipped channel
// only while C < y) + the opacity, distortion and sparsity terms, and writes per sample the gradient with respect to
// log σ and to the log radiance of each channel (times gradient_scale; C held fixed in the denominator as sg(C)), and
// the sample's rendering weight T·α.
double RayLossAndGradient(const RaySample* samples, size_t count, const float target[3], const RayLossTerms& terms,
                          float* g_log_sigma, Vec3f* g_log_color, float* weights);

}  // namespace nerf_train_detail

class NerfTrainer {
 public:
  NerfTrainer(const NerfTrainData& data, const NerfTrainOptions& options);
  ~NerfTrainer();
  NerfTrainer(const NerfTrainer&) = delete;
  NerfTrainer& operator=(const NerfTrainer&) = delete;

  // One optimisation step; returns the batch loss (mean per ray and channel).
  double Step();
  // True once the schedule is complete.
  bool Done() const;
  int step() const;
  int level() const;
  double progress() const;         // schedule position in [0, 1]
  double elapsed_seconds() const;  // training time, carried over checkpoints
  const NerfField& field() const;

  // psnr_tm (mean over views) of the held-out views (first `max_views`, 0: all) rendered from the current field.
  double HeldOutPsnr(int max_views) const;
  // The field in its final form (occupancy refreshed, the training cameras as its capture_centres) for saving.
  NerfField FinalField() const;

  // Checkpoints: the whole training state (field, Adam moments, step, time),
  // written atomically (version kNerfCheckpointVersion; earlier ones load too).
  // Loading checks that options and data match.
  void SaveCheckpoint(const std::string& path) const;
  void LoadCheckpoint(const std::string& path);

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace nerfar

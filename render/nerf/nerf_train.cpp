#include "render/nerf/nerf_train.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "calib/core/atomic_file.h"
#include "calib/core/binary_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/core/metrics.h"
#include "calib/core/option_fields.h"
#include "calib/core/parallel.h"
#include "calib/core/random.h"
#include "calib/linear_image.h"
#include "calib/scene_box.h"
#include "render/nerf/nerf_internal.h"

namespace nerfar {

using nerf_detail::Corners;

// ------------------------------------------------------------------ data

namespace {

// The views of one split, loaded in parallel.
std::vector<NerfView> LoadViews(const Dataset& set, const Linearisation& linearisation) {
  std::vector<NerfView> views(set.frames.size());
  ParallelFor(
      set.frames.size(),
      [&](size_t n) {
        const DatasetFrame& frame = set.frames[n];
        NerfView& v = views[n];
        v.name = std::filesystem::path(frame.file_path).stem().string();
        v.image_path = frame.image_path;
        v.camera = set.CameraOf(frame);
        v.T_world_camera = frame.T_world_camera;
        LinearImage image = ReadLinearImage(frame.image_path, linearisation);
        v.rgb = std::move(image.rgb);
        v.clipped = std::move(image.clipped);
        if (v.rgb.width != v.camera.width || v.rgb.height != v.camera.height)
          ThrowInputError(frame.image_path, "image is " + std::to_string(v.rgb.width) + "x" +
                                                std::to_string(v.rgb.height) + " (expected " +
                                                std::to_string(v.camera.width) + "x" + std::to_string(v.camera.height) +
                                                " from the transforms file)");
        for (float& x : v.rgb.pixels) x = std::max(x, 0.0f);  // radiance is non-negative
        if (!frame.mask_path.empty()) v.mask = ReadMask(frame.mask_path, v.camera.width, v.camera.height);
      },
      1);
  return views;
}

// One log line on how display-referred frames were read, and how much clipped.
void LogLinearisation(const std::vector<NerfView>& views, const Linearisation& linearisation) {
  size_t display = 0, pixels = 0, clipped = 0;
  for (const NerfView& v : views) {
    if (v.clipped.empty()) continue;
    ++display;
    pixels += v.clipped.PixelCount();
    for (std::uint8_t flags : v.clipped.pixels) clipped += flags != 0;
  }
  if (display == 0) return;
  char share[32];
  std::snprintf(share, sizeof share, "%.2f%%", 100.0 * double(clipped) / double(std::max<size_t>(pixels, 1)));
  LogInfo("train: " + std::to_string(display) + " PNG/JPEG images linearised through " + linearisation.Describe() +
          "; " + share + " of their pixels clipped (a lower bound in training)");
}

}  // namespace

NerfTrainData ReadNerfTrainData(const std::string& dataset_dir) {
  NerfTrainData data;
  const Dataset train = ReadDataset(DatasetSplitPath(dataset_dir, "train"));
  if (train.aabb) {
    data.aabb = *train.aabb;
  } else {
    const std::string board_path = (std::filesystem::path(dataset_dir) / "board.json").string();
    std::error_code board_error;
    std::optional<Board> board;
    if (std::filesystem::is_regular_file(board_path, board_error)) board = ReadBoard(board_path);
    const SceneBox box = DeriveSceneBox(train, board ? &*board : nullptr);
    data.aabb = box.box;
    LogInfo("train: " + train.path + " gives no aabb: " + box.how);
  }
  data.source = train.path;
  const Linearisation linearisation = DatasetLinearisation(dataset_dir);
  data.train = LoadViews(train, linearisation);
  const std::string test_path = DatasetSplitPath(dataset_dir, "test");
  std::error_code error;
  if (std::filesystem::is_regular_file(test_path, error))
    data.held_out = LoadViews(ReadDataset(test_path), linearisation);
  LogLinearisation(data.train, linearisation);
  if (data.train.empty()) ThrowInputError(train.path, "no training frames (expected at least one)");
  return data;
}

// --------------------------------------------------------------- options

NerfTrainOptions NerfTrainOptions::Preset(const std::string& name) {
  NerfTrainOptions o;
  if (name == "fast") {
    // 1100 steps, the 5 mm level from step 242. The log-density's learning
    // rate is doubled: in so short a schedule the density ramps of surfaces
    // otherwise stay soft (their T = 0.5 point centimetres in front of them),
    // and sharper ramps also leave fewer occupied cells, so steps get cheaper;
    // twice that gains nothing more (docs/history/nerf.md, "Preset choices").
    o.steps = 1100;
    o.rays_per_step = 4096;
    o.coarse_voxel_m = 0.01;
    o.levels = 2;
    o.last_level_start = 0.22;
    o.lr_density = 0.2;
    // Cells under σ = 5/m are dropped from the saved model: at 5 mm voxels
    // that is faint fog, and the file shrinks by about 40 % with psnr within
    // ±0.3 dB; at balanced's 2.5 mm voxels the same cut removes real detail.
    o.save_occupancy_sigma = 5.0;
    // Once the 5 mm level has settled, training skips the cells the saved
    // model will drop anyway: about half the CPU time, the same quality.
    o.occupancy_sigma_finest = 5.0;
    // The foreground penalty at full weight: surfaces seen only at grazing
    // angles (the far part of a table) otherwise stay translucent and their
    // T = 0.5 point falls behind them (NerfTrainOptions::foreground_weight).
    o.foreground_weight = 1.0;
  } else if (name == "balanced") {
    o.steps = 2500;
    o.rays_per_step = 8192;
    o.coarse_voxel_m = 0.01;
    o.levels = 3;
    o.last_level_start = 0.45;
  } else if (name == "accurate") {
    o.steps = 5000;
    o.rays_per_step = 8192;
    o.coarse_voxel_m = 0.01;
    o.levels = 3;
    // The coarse levels take balanced's step counts (1 cm: steps 0-562, 5 mm:
    // 563-1124; level l starts at last_level_start · l / (levels - 1)), the
    // rest is the 2.5 mm level. Longer coarse levels learn a plain, textureless
    // table as a translucent slab under its top, which the finest level does
    // not remove (docs/history/nerf.md, "Preset choices").
    o.last_level_start = 0.225;
    // As fast: the foreground penalty at full weight.
    o.foreground_weight = 1.0;
    o.step_voxels = 0.4;
  } else {
    throw InputError("preset '" + name + "' (expected fast, balanced or accurate)");
  }
  return o;
}

std::vector<std::string> NerfTrainOptions::Validate() const {
  std::vector<std::string> p;
  auto check = [&](bool ok, const std::string& what) {
    if (!ok) p.push_back(what);
  };
  check(steps >= 1 && steps <= 10000000, "steps: " + std::to_string(steps) + " (expected 1..1e7)");
  check(rays_per_step >= 1 && rays_per_step <= (1 << 22),
        "rays_per_step: " + std::to_string(rays_per_step) + " (expected 1..4194304)");
  check(coarse_voxel_m > 1e-4 && coarse_voxel_m < 1.0,
        "coarse_voxel_m: " + std::to_string(coarse_voxel_m) + " (expected 1e-4..1 m)");
  check(levels >= 1 && levels <= 6, "levels: " + std::to_string(levels) + " (expected 1..6)");
  check(last_level_start >= 0 && last_level_start < 1, "last_level_start: (expected 0 <= x < 1)");
  check(step_voxels > 0.05 && step_voxels <= 2, "step_voxels: (expected 0.05..2)");
  check(lr_density > 0 && lr_density < 10 && lr_color > 0 && lr_color < 10, "lr_density, lr_color: (expected 0..10)");
  check(lr_final_factor > 0 && lr_final_factor <= 1, "lr_final_factor: (expected 0 < x <= 1)");
  check(color_slope_decay >= 0 && color_slope_decay * lr_color < 1,
        "color_slope_decay: (expected >= 0 with color_slope_decay * lr_color < 1)");
  check(tv_density >= 0 && tv_color >= 0, "tv_density, tv_color: (expected >= 0)");
  check(background_weight >= 0, "background_weight: (expected >= 0)");
  check(foreground_weight >= 0, "foreground_weight: (expected >= 0)");
  check(distortion_weight >= 0 && distortion_weight < 1e3, "distortion_weight: (expected 0..1000 per metre)");
  check(sparsity_weight >= 0 && sparsity_weight < 1e3, "sparsity_weight: (expected 0..1000)");
  check(loss_epsilon > 0, "loss_epsilon: (expected > 0)");
  check(occupancy_every >= 1, "occupancy_every: (expected >= 1)");
  check(occupancy_sigma >= 0 && occupancy_sigma < 1e3, "occupancy_sigma: (expected 0..1000 per metre)");
  check(occupancy_sigma_finest >= 0 && occupancy_sigma_finest < 1e3,
        "occupancy_sigma_finest: (expected 0..1000 per metre)");
  check(save_occupancy_sigma >= 0 && save_occupancy_sigma < 1e3, "save_occupancy_sigma: (expected 0..1000 per metre)");
  check(prune_delay >= 0, "prune_delay: (expected >= 0)");
  check(prune_weight >= 0 && prune_weight < 1, "prune_weight: (expected 0 <= x < 1)");
  check(prune_every >= 1, "prune_every: (expected >= 1)");
  check(prune_relative >= 0 && prune_relative < 1, "prune_relative: (expected 0 <= x < 1)");
  check(initial_sigma > 0 && initial_sigma < 1e4, "initial_sigma: (expected 0..1e4 per metre)");
  check(max_seconds >= 0, "max_seconds: (expected >= 0)");
  check(eval_views >= 0, "eval_views: (expected >= 0)");
  return p;
}

namespace {
// One table of the options' fields, so ToJson and Set never drift apart.
std::vector<OptionField> Fields(NerfTrainOptions& o) {
  return {FieldOf("steps", &o.steps),
          FieldOf("rays_per_step", &o.rays_per_step),
          FieldOf("coarse_voxel_m", &o.coarse_voxel_m),
          FieldOf("levels", &o.levels),
          FieldOf("last_level_start", &o.last_level_start),
          FieldOf("step_voxels", &o.step_voxels),
          FieldOf("lr_density", &o.lr_density),
          FieldOf("lr_color", &o.lr_color),
          FieldOf("lr_final_factor", &o.lr_final_factor),
          FieldOf("color_slope_decay", &o.color_slope_decay),
          FieldOf("tv_density", &o.tv_density),
          FieldOf("tv_color", &o.tv_color),
          FieldOf("background_weight", &o.background_weight),
          FieldOf("foreground_weight", &o.foreground_weight),
          FieldOf("distortion_weight", &o.distortion_weight),
          FieldOf("sparsity_weight", &o.sparsity_weight),
          FieldOf("loss_epsilon", &o.loss_epsilon),
          FieldOf("occupancy_every", &o.occupancy_every),
          FieldOf("occupancy_sigma", &o.occupancy_sigma),
          FieldOf("occupancy_sigma_finest", &o.occupancy_sigma_finest),
          FieldOf("save_occupancy_sigma", &o.save_occupancy_sigma),
          FieldOf("prune_delay", &o.prune_delay),
          FieldOf("prune_weight", &o.prune_weight),
          FieldOf("prune_every", &o.prune_every),
          FieldOf("prune_relative", &o.prune_relative),
          FieldOf("initial_sigma", &o.initial_sigma),
          FieldOf("seed", &o.seed),
          FieldOf("max_seconds", &o.max_seconds),
          FieldOf("eval_views", &o.eval_views)};
}
}  // namespace

std::string NerfTrainOptions::ToJson() const {
  NerfTrainOptions copy = *this;
  return OptionFieldsJson(Fields(copy));
}

void NerfTrainOptions::Set(const std::string& key_value) { SetOptionField(Fields(*this), key_value); }

// --------------------------------------------------------------- trainer

namespace {

constexpr size_t kRaysPerChunk = 256;  // fixed chunking: results independent of threads
constexpr int kScatterParts = 2;       // fixed slot partitions for the gradient scatter
constexpr float kTrainMinTransmittance = 1e-4f;

struct Sample {
  Corners corners;
  nerf_train_detail::RaySample ray;
};

// The gradient a sample sends to its 8 corners.
struct Record {
  int32_t slot[8];
  float weight[8];
  float g_density;   // dL/d(raw density)
  float g_color[3];  // dL/d(log radiance) per channel
  float w;           // the sample's rendering weight T·α (for pruning)
  Vec3f dir;
};

}  // namespace

namespace nerf_train_detail {

double RayLossAndGradient(const RaySample* s, size_t n, const float target[3], const RayLossTerms& terms,
                          float* g_log_sigma, Vec3f* g_log_color, float* weights) {
  // Forward: α, weights w = T α, colour C and opacity O.
  float transmittance = 1.0f;
  Vec3f color;
  for (size_t i = 0; i < n; ++i) {
    const float alpha = -std::expm1(-s[i].sigma * s[i].dt);
    weights[i] = transmittance * alpha;
    color += s[i].color * weights[i];
    transmittance *= 1.0f - alpha;
  }
  const float opacity = 1.0f - transmittance;
  const float scale = terms.gradient_scale, eps = terms.epsilon;
  // Loss and its gradient with respect to the rendered colour and opacity.
  double loss = 0.0;
  float g_c[3];
  for (int ch = 0; ch < 3; ++ch) {
    const float pred = color[ch], denom = pred + eps;
    // A clipped channel says only that the radiance is at least the target.
    const bool bound_met = (terms.clipped_channels >> ch & 1u) != 0 && pred >= target[ch];
    const float diff = bound_met ? 0.0f : pred - target[ch];
    loss += double(diff) * diff / (double(denom) * denom) / 3.0;
    g_c[ch] = 2.0f * diff / (denom * denom) / 3.0f * scale;
  }
  float g_o = 0.0f;
  if (terms.opacity_weight > 0.0f) {
    const float miss = opacity - terms.opacity_target;
    loss += double(terms.opacity_weight) * miss * miss;
    g_o = 2.0f * terms.opacity_weight * miss * scale;
  }
  // Distortion prior: dL/dw_i = λ (2 Σ_j w_j |t_i - t_j| + 2 w_i δ_i / 3), the
  // sum split at i into prefix and suffix sums of w and w·t (samples are in
  // order of t). Its density gradient follows the colour's form with the
  // per-sample "colour" dL/dw_i: suffix_w = Σ_{j>i} w_j dL/dw_j. g_w holds
  // dL/dw_i in g_log_sigma until the backward pass below overwrites it.
  const float dist_w = terms.distortion_weight;
  float* g_w = g_log_sigma;
  float suffix_w = 0.0f;
  if (dist_w > 0.0f && n > 0) {
    double w_all = 0, wt_all = 0;
    for (size_t i = 0; i < n; ++i) {
      w_all += weights[i];
      wt_all += double(weights[i]) * s[i].t;
    }
    double w_before = 0, wt_before = 0, dist = 0;
    for (size_t i = 0; i < n; ++i) {
      const double w = weights[i], t = s[i].t;
      const double w_after = w_all - w_before - w, wt_after = wt_all - wt_before - w * t;
      const double spread = t * w_before - wt_before + wt_after - t * w_after;
      dist += w * spread + w * w * s[i].dt / 3.0;
      g_w[i] = float(dist_w * (2.0 * spread + 2.0 * w * s[i].dt / 3.0) * scale);
      suffix_w += float(w) * g_w[i];
      w_before += w;
      wt_before += w * t;
    }
    loss += double(dist_w) * dist;
  } else {
    for (size_t i = 0; i < n; ++i) g_w[i] = 0.0f;
  }
  const float sparse_w = terms.sparsity_weight, sparse_g = sparse_w * scale;
  if (sparse_w > 0.0f) {
    double alpha_sum = 0;
    for (size_t i = 0; i < n; ++i) alpha_sum += -std::expm1(-s[i].sigma * s[i].dt);
    loss += double(sparse_w) * alpha_sum;
  }
  // Backward (front to back with the suffix colour S_i = C - prefix).
  float t_i = 1.0f;
  Vec3f prefix;
  for (size_t i = 0; i < n; ++i) {
    const float alpha = -std::expm1(-s[i].sigma * s[i].dt);
    const float w = t_i * alpha;
    const float t_next = t_i * (1.0f - alpha);
    prefix += s[i].color * w;
    const Vec3f suffix = color - prefix;
    float g_raw = 0.0f;
    for (int ch = 0; ch < 3; ++ch) {
      g_raw += g_c[ch] * (t_next * s[i].color[ch] - suffix[ch]);
      g_log_color[i][ch] = g_c[ch] * w * s[i].color[ch];
    }
    g_raw += g_o * transmittance;
    suffix_w -= w * g_w[i];
    g_raw += t_next * g_w[i] - suffix_w;
    g_raw += sparse_g * (1.0f - alpha);  // d(λ α)/d(σ δ)
    g_log_sigma[i] = g_raw * s[i].dt * s[i].sigma;
    t_i = t_next;
  }
  return loss;
}

}  // namespace nerf_train_detail

struct NerfTrainer::State {
  const NerfTrainData& data;
  NerfTrainOptions options;
  NerfField field;
  int step = 0;
  int level = 0;
  int adam_t = 0;             // Adam steps since the level started (bias correction)
  double elapsed_before = 0;  // seconds trained before this process (checkpoints)
  std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
  double epsilon = 1;                   // absolute ε of the loss
  std::vector<uint64_t> pixel_offsets;  // prefix sums of training pixel counts

  // Optimiser state, per slot.
  std::vector<float> m_density, v_density, g_density;
  std::vector<float> m_color, v_color, g_color;
  std::vector<uint8_t> touched;
  std::vector<float> max_weight;                    // per slot: largest sample weight T·α since the last prune
  std::vector<std::vector<Record>> records;         // per chunk
  std::vector<std::vector<int32_t>> touched_lists;  // per block of slots: the touched ones, in slot order
  std::vector<int32_t> all_touched;                 // every touched slot, ascending (memory order)
  size_t scatter_split = 0;                         // first slot of the second scatter part (0: the middle)
  // Measurement for the verbose log: seconds per phase and samples since the last report.
  double time_march = 0, time_scatter = 0, time_adam = 0, time_occupancy = 0;
  double wall_march = 0, wall_scatter = 0, wall_adam = 0, wall_occupancy = 0;  // the same phases, wall-clock
  uint64_t samples_marched = 0, rays_marched = 0, vertices_updated = 0;

  explicit State(const NerfTrainData& d) : data(d) {}

  double Elapsed() const {
    return elapsed_before + std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  double Progress() const {
    double p = double(step) / options.steps;
    if (options.max_seconds > 0) p = std::max(p, Elapsed() / options.max_seconds);
    return std::min(p, 1.0);
  }
  double LevelStart(int l) const {
    if (l == 0) return 0.0;
    return options.last_level_start * double(l) / double(options.levels - 1);
  }
  // The training occupancy threshold: occupancy_sigma, or occupancy_sigma_finest
  // at the finest level once its prune delay has passed.
  float OccupancySigma() const {
    const bool finest = level == options.levels - 1 && (options.levels == 1 || adam_t > options.prune_delay);
    return float(finest && options.occupancy_sigma_finest > 0 ? options.occupancy_sigma_finest
                                                              : options.occupancy_sigma);
  }
  void ResetOptimiser() {
    const size_t n = field.SlotCount();
    m_density.assign(n, 0.0f);
    v_density.assign(n, 0.0f);
    g_density.assign(n, 0.0f);
    m_color.assign(n * kNerfColorCoeffs, 0.0f);
    v_color.assign(n * kNerfColorCoeffs, 0.0f);
    g_color.assign(n * kNerfColorCoeffs, 0.0f);
    touched.assign(n, 0);
    max_weight.assign(n, 0.0f);
    adam_t = 0;
  }
  void PruneByWeight();
  void Upsample();
  // One step of training; returns the batch's mean loss.
  double DoStep();
  struct StepSettings;
  struct PixelRay;
  struct RayScratch;
  class PhaseClock;
  // DoStep's phases, in order.
  void AdvanceLevel(double progress);  // upsample to the level the schedule has reached
  StepSettings MakeStepSettings() const;
  double MarchRays(const StepSettings& settings);  // the batch's records and summed loss
  std::optional<PixelRay> PickPixelRay(const StepSettings& settings, size_t r) const;
  void TrainRay(PixelRay p, const StepSettings& settings, RayScratch& scratch, double& loss_sum,
                std::vector<Record>& out) const;
  void ScatterGradients();
  void UpdateTouchedVertices(float lr_density, float lr_color);
  void CollectTouched();
  void AddTvGradient();
  void AdamUpdate(float lr_density, float lr_color);
  void UpdateOccupancyOnSchedule();
  void LogPhaseTimes();
};

void NerfTrainer::State::Upsample() {
  const NerfField& old = field;
  NerfField next;
  next.aabb = old.aabb;
  next.origin = old.origin;
  next.voxel_m = old.voxel_m * 0.5f;
  for (int a = 0; a < 3; ++a) {
    const double extent = old.aabb.max[a] - old.aabb.min[a];
    next.res[a] = std::max(2, int(std::ceil(extent / next.voxel_m - 1e-6)) + 1);
    next.bricks[a] = (next.res[a] + 3) / 4;
  }
  next.brick_table.assign(size_t(next.bricks[0]) * next.bricks[1] * next.bricks[2], -1);
  // New bricks around every occupied old cell (dilated by one old cell), in table order.
  std::vector<uint8_t> wanted(next.brick_table.size(), 0);
  for (size_t b = 0; b < old.BrickCount(); ++b) {
    const uint64_t bits = old.occupancy[b];
    if (!bits) continue;
    for (int cell = 0; cell < 64; ++cell) {
      if (!((bits >> cell) & 1u)) continue;
      const int c[3] = {old.brick_coords[3 * b] * 4 + (cell & 3), old.brick_coords[3 * b + 1] * 4 + ((cell >> 2) & 3),
                        old.brick_coords[3 * b + 2] * 4 + (cell >> 4)};
      int lo[3], hi[3];
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::max(0, (2 * (c[a] - 1)) / 4);
        hi[a] = std::min(next.bricks[a] - 1, (2 * (c[a] + 2)) / 4);
      }
      for (int z = lo[2]; z <= hi[2]; ++z)
        for (int y = lo[1]; y <= hi[1]; ++y)
          for (int x = lo[0]; x <= hi[0]; ++x) wanted[(size_t(z) * next.bricks[1] + y) * next.bricks[0] + x] = 1;
    }
  }
  for (int z = 0; z < next.bricks[2]; ++z)
    for (int y = 0; y < next.bricks[1]; ++y)
      for (int x = 0; x < next.bricks[0]; ++x)
        if (wanted[(size_t(z) * next.bricks[1] + y) * next.bricks[0] + x]) next.AllocateBrick(x, y, z);
  // Values by trilinear interpolation of the old grid.
  ParallelFor(
      next.BrickCount(),
      [&](size_t b) {
        for (int v = 0; v < kNerfBrickSlots; ++v) {
          const int i = next.brick_coords[3 * b] * 4 + (v & 3), j = next.brick_coords[3 * b + 1] * 4 + ((v >> 2) & 3),
                    k = next.brick_coords[3 * b + 2] * 4 + (v >> 4);
          const size_t s = b * kNerfBrickSlots + v;
          Corners c;
          const Vec3f g(float(i) * 0.5f, float(j) * 0.5f, float(k) * 0.5f);
          if (i >= next.res[0] || j >= next.res[1] || k >= next.res[2] || !nerf_detail::LocateGrid(old, g, c)) continue;
          next.density[s] = nerf_detail::RawDensity(old, c);
          nerf_detail::ColorCoeffs(old, c, &next.color[s * kNerfColorCoeffs]);
        }
      },
      16);
  next.UpdateOccupancy(OccupancySigma());
  field = std::move(next);
  ResetOptimiser();
}

// The settings one step shares across its rays.
struct NerfTrainer::State::StepSettings {
  size_t batch = 0;                       // rays this step
  float step_m = 0;                       // sample spacing along a ray
  float background_weight = 0;            // opacity → 0 on black (background) pixels
  float foreground_weight = 0;            // opacity → 1 inside the object, away from silhouettes
  float prune_relative = 0;               // see NerfTrainOptions::prune_relative (finest level only)
  uint64_t step_key = 0;                  // seeds this step's random pixels, jitter and offsets
  nerf_train_detail::RayLossTerms terms;  // the loss terms every ray shares
};

// One training ray: its pixel, the pixel's target radiance and what the pixel says about opacity.
struct NerfTrainer::State::PixelRay {
  NerfRay ray;
  const float* target = nullptr;  // linear RGB
  uint8_t clipped_channels = 0;   // bit c: channel c clipped, its target a lower bound
  uint64_t offset_hash = 0;       // the first sample's offset along the ray
  bool background = false;        // a black pixel: nothing there
  bool foreground = false;        // inside the object, not beside a silhouette
};

// Per-thread buffers of one ray's samples, reused from ray to ray.
struct NerfTrainer::State::RayScratch {
  std::vector<Sample> samples;
  std::vector<nerf_train_detail::RaySample> ray_samples;
  std::vector<float> g_log_sigma, weights;
  std::vector<Vec3f> g_log_color;
};

// Process CPU seconds (all threads: comparable under load) and wall-clock seconds
// of the phases of a step, added to the State's totals for the verbose log.
class NerfTrainer::State::PhaseClock {
 public:
  PhaseClock() : cpu_(CpuNow()), wall_(WallNow()) {}
  // Adds the time since the last lap to the phase's totals and starts the next phase.
  void Lap(double& cpu_total, double& wall_total) {
    const double cpu = CpuNow(), wall = WallNow();
    cpu_total += cpu - cpu_;
    wall_total += wall - wall_;
    cpu_ = cpu, wall_ = wall;
  }

 private:
  static double CpuNow() {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
  }
  static double WallNow() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  }
  double cpu_, wall_;
};

double NerfTrainer::State::DoStep() {
  const double progress = Progress();
  AdvanceLevel(progress);
  const StepSettings settings = MakeStepSettings();
  PhaseClock clock;
  const double loss = MarchRays(settings);
  clock.Lap(time_march, wall_march);
  ScatterGradients();
  clock.Lap(time_scatter, wall_scatter);
  // The learning rates fall geometrically to lr_final_factor over the schedule.
  const double lr_scale = std::pow(options.lr_final_factor, progress);
  UpdateTouchedVertices(float(options.lr_density * lr_scale), float(options.lr_color * lr_scale));
  clock.Lap(time_adam, wall_adam);
  ++step;
  UpdateOccupancyOnSchedule();
  clock.Lap(time_occupancy, wall_occupancy);
  if (step % 50 == 0) LogPhaseTimes();
  return loss / double(settings.batch);
}

void NerfTrainer::State::AdvanceLevel(double progress) {
  while (level + 1 < options.levels && progress >= LevelStart(level + 1)) {
    Upsample();
    ++level;
  }
}

NerfTrainer::State::StepSettings NerfTrainer::State::MakeStepSettings() const {
  StepSettings s;
  s.batch = size_t(options.rays_per_step);
  s.step_m = float(options.step_voxels) * field.voxel_m;
  s.background_weight = float(options.background_weight);
  s.foreground_weight = float(options.foreground_weight);
  s.prune_relative = level == options.levels - 1 ? float(options.prune_relative) : 0.0f;
  s.step_key = Mix64(options.seed * 0x9e37ull + uint64_t(step));
  s.terms.epsilon = float(epsilon);
  s.terms.gradient_scale = 1.0f / float(s.batch);  // the loss is the batch's mean
  s.terms.distortion_weight = float(options.distortion_weight);
  s.terms.sparsity_weight = float(options.sparsity_weight);
  return s;
}

// Marches the batch in fixed chunks of rays (so the records, and every sum over
// them, do not depend on the thread count); returns the batch's summed loss.
double NerfTrainer::State::MarchRays(const StepSettings& settings) {
  const size_t chunks = (settings.batch + kRaysPerChunk - 1) / kRaysPerChunk;
  records.resize(chunks);
  std::vector<double> chunk_loss(chunks, 0.0);
  ParallelForChunks(chunks, 1, [&](size_t chunk_begin, size_t chunk_end) {
    thread_local RayScratch scratch;
    for (size_t chunk = chunk_begin; chunk < chunk_end; ++chunk) {
      std::vector<Record>& out = records[chunk];
      out.clear();
      double loss_sum = 0.0;
      const size_t r_end = std::min(settings.batch, (chunk + 1) * kRaysPerChunk);
      for (size_t r = chunk * kRaysPerChunk; r < r_end; ++r)
        if (const std::optional<PixelRay> p = PickPixelRay(settings, r)) TrainRay(*p, settings, scratch, loss_sum, out);
      chunk_loss[chunk] = loss_sum;
    }
  });
  for (const std::vector<Record>& chunk : records) samples_marched += chunk.size();
  rays_marched += settings.batch;
  double loss = 0.0;
  for (double l : chunk_loss) loss += l;
  return loss;
}

// Ray r of the step: a pixel drawn uniformly over every training pixel, jittered inside it;
// none where the pixel is masked (it teaches nothing, not even whether something is there).
std::optional<NerfTrainer::State::PixelRay> NerfTrainer::State::PickPixelRay(const StepSettings& settings,
                                                                             size_t r) const {
  const uint64_t h0 = Mix64(settings.step_key ^ Mix64(r));
  const uint64_t h1 = Mix64(h0), h2 = Mix64(h1), h3 = Mix64(h2);
  const uint64_t pixel = h0 % pixel_offsets.back();
  const size_t view_index =
      size_t(std::upper_bound(pixel_offsets.begin(), pixel_offsets.end(), pixel) - pixel_offsets.begin()) - 1;
  const NerfView& view = data.train[view_index];
  const uint64_t local = pixel - pixel_offsets[view_index];
  const int px = int(local % uint64_t(view.camera.width)), py = int(local / uint64_t(view.camera.width));
  if (!view.mask.empty() && view.mask.at(px, py) == 0) return std::nullopt;
  const double sx = px + UnitFloat(h1), sy = py + UnitFloat(h2);
  const Vec3 dir_c =
      view.camera.HasDistortion()
          ? Unproject(view.camera, {sx, sy})
          : Normalized(Vec3((sx - view.camera.cx) / view.camera.fx, (sy - view.camera.cy) / view.camera.fy, 1.0));
  PixelRay p;
  p.ray.origin = Vec3f(view.T_world_camera.translation);
  p.ray.dir = Vec3f(view.T_world_camera.Rotate(dir_c));
  p.target = view.rgb.Pixel(px, py);
  if (!view.clipped.empty()) p.clipped_channels = view.clipped.at(px, py);
  p.offset_hash = h3;
  auto is_zero = [&](int x, int y) {
    const float* q = view.rgb.Pixel(x, y);
    return q[0] == 0.0f && q[1] == 0.0f && q[2] == 0.0f;
  };
  p.background = is_zero(px, py);
  // Foreground (opaque) only away from silhouettes: a pixel partly covered is not 0,
  // yet a jittered ray through it may pass beside the object.
  p.foreground = settings.foreground_weight > 0.0f && !p.background && px > 0 && py > 0 && px + 1 < view.camera.width &&
                 py + 1 < view.camera.height && !is_zero(px - 1, py) && !is_zero(px + 1, py) && !is_zero(px, py - 1) &&
                 !is_zero(px, py + 1);
  return p;
}

// One ray: its loss is added to loss_sum, its samples' gradients appended to `out` as records.
void NerfTrainer::State::TrainRay(PixelRay p, const StepSettings& settings, RayScratch& scratch, double& loss_sum,
                                  std::vector<Record>& out) const {
  NerfRay& ray = p.ray;
  if (!IntersectAabb(field.aabb, ray.origin, ray.dir, ray.t_near, ray.t_far)) {
    // Nothing to learn from a ray outside the box; count its (constant) loss.
    const float eps = settings.terms.epsilon;
    for (int ch = 0; ch < 3; ++ch) loss_sum += double(p.target[ch]) * p.target[ch] / (double(eps) * eps) / 3.0;
    return;
  }
  // Forward: the samples in occupied cells until the transmittance is spent.
  std::vector<Sample>& samples = scratch.samples;
  samples.clear();
  float transmittance = 1.0f;
  nerf_detail::MarchRay(field, ray, settings.step_m, UnitFloat(p.offset_hash),
                        [&](float t, float dt, const Corners& c) {
                          Sample s;
                          s.corners = c;
                          s.ray.t = t;
                          s.ray.dt = dt;
                          s.ray.sigma = std::exp(nerf_detail::RawDensity(field, c));
                          float q[kNerfColorCoeffs];
                          nerf_detail::ColorCoeffs(field, c, q);
                          s.ray.color = nerf_detail::ColorFromCoeffs(q, ray.dir);
                          transmittance *= 1.0f + std::expm1(-s.ray.sigma * dt);  // 1 - α, as RayLossAndGradient
                          samples.push_back(s);
                          return transmittance >= kTrainMinTransmittance;
                        });
  const size_t n = samples.size();
  scratch.ray_samples.resize(n);
  scratch.g_log_sigma.resize(n);
  scratch.g_log_color.resize(n);
  scratch.weights.resize(n);
  for (size_t i = 0; i < n; ++i) scratch.ray_samples[i] = samples[i].ray;
  nerf_train_detail::RayLossTerms terms = settings.terms;
  terms.clipped_channels = p.clipped_channels;
  if (p.background) {
    terms.opacity_weight = settings.background_weight;
    terms.opacity_target = 0.0f;
  } else if (p.foreground) {
    terms.opacity_weight = settings.foreground_weight;
    terms.opacity_target = 1.0f;
  }
  loss_sum +=
      nerf_train_detail::RayLossAndGradient(scratch.ray_samples.data(), n, p.target, terms, scratch.g_log_sigma.data(),
                                            scratch.g_log_color.data(), scratch.weights.data());
  // Samples below this weight do not count as seen for pruning (prune_relative).
  float seen_min = 0.0f;
  if (settings.prune_relative > 0.0f) {
    float peak = 0.0f;
    for (float w : scratch.weights) peak = std::max(peak, w);
    seen_min = settings.prune_relative * peak;
  }
  for (size_t i = 0; i < n; ++i) {
    Record rec;
    rec.g_density = scratch.g_log_sigma[i];
    for (int ch = 0; ch < 3; ++ch) rec.g_color[ch] = scratch.g_log_color[i][ch];
    rec.w = scratch.weights[i] >= seen_min ? scratch.weights[i] : 0.0f;
    std::memcpy(rec.slot, samples[i].corners.slot, sizeof rec.slot);
    std::memcpy(rec.weight, samples[i].corners.weight, sizeof rec.weight);
    rec.dir = ray.dir;
    out.push_back(rec);
  }
}

// Scatters the records into the gradient arrays: partition p owns a slot
// range and walks all records in chunk order, so sums are deterministic.
void NerfTrainer::State::ScatterGradients() {
  const size_t slots = field.SlotCount();
  ParallelForChunks(kScatterParts, 1, [&](size_t part_begin, size_t part_end) {
    for (size_t part = part_begin; part < part_end; ++part) {
      // Two parts split at the median slot touched by the previous step, so both get
      // about the same work (each slot's sum is in record order whatever the split).
      const size_t split = scatter_split > 0 && scatter_split < slots ? scatter_split : slots / 2;
      static_assert(kScatterParts == 2);
      const int32_t lo = part == 0 ? 0 : int32_t(split), hi = part == 0 ? int32_t(split) : int32_t(slots);
      for (const std::vector<Record>& chunk : records)
        for (const Record& rec : chunk) {
          for (int n = 0; n < 8; ++n) {
            const int32_t s = rec.slot[n];
            if (s < lo || s >= hi) continue;
            const float w = rec.weight[n];
            touched[s] = 1;
            g_density[s] += w * rec.g_density;
            max_weight[s] = std::max(max_weight[s], rec.w);
            float* g = &g_color[size_t(s) * kNerfColorCoeffs];
            for (int ch = 0; ch < 3; ++ch) {
              const float gc = w * rec.g_color[ch];
              g[4 * ch] += gc;
              g[4 * ch + 1] += gc * rec.dir.x;
              g[4 * ch + 2] += gc * rec.dir.y;
              g[4 * ch + 3] += gc * rec.dir.z;
            }
          }
        }
    }
  });
}

// Sparse Adam on the vertices this step touched, with the TV prior's gradient.
void NerfTrainer::State::UpdateTouchedVertices(float lr_density, float lr_color) {
  ++adam_t;
  CollectTouched();
  // The TV prior's gradient first, reading the parameters only (each vertex adds
  // to its own gradient), then Adam in place: the order of the vertices does not matter.
  if (float(options.tv_density) > 0 || float(options.tv_color) > 0) AddTvGradient();
  AdamUpdate(lr_density, lr_color);
}

// all_touched: the touched slots in ascending order (the update then walks memory in order).
void NerfTrainer::State::CollectTouched() {
  const size_t slots = field.SlotCount();
  constexpr size_t kScanBlocks = 64;
  touched_lists.resize(kScanBlocks);
  ParallelFor(
      kScanBlocks,
      [&](size_t block) {
        std::vector<int32_t>& list = touched_lists[block];
        list.clear();
        const size_t lo = slots * block / kScanBlocks, hi = slots * (block + 1) / kScanBlocks;
        for (size_t s = lo; s < hi; ++s)
          if (touched[s]) list.push_back(int32_t(s));
      },
      1);
  all_touched.clear();
  for (const auto& list : touched_lists) all_touched.insert(all_touched.end(), list.begin(), list.end());
  vertices_updated += all_touched.size();
  scatter_split = all_touched.empty() ? 0 : size_t(all_touched[all_touched.size() / 2]);
}

// Adds the gradient of the TV prior (squared differences to the 6 grid neighbours
// that exist; log-densities floored at -10 so empty space does not pull) to every touched vertex.
void NerfTrainer::State::AddTvGradient() {
  const float tv_d = float(options.tv_density), tv_c = float(options.tv_color);
  ParallelFor(
      all_touched.size(),
      [&](size_t n) {
        const int32_t s = all_touched[n];
        const size_t b = size_t(s) / kNerfBrickSlots;
        const int v = s % kNerfBrickSlots;
        const int local[3] = {v & 3, (v >> 2) & 3, v >> 4};
        const int ijk[3] = {field.brick_coords[3 * b] * 4 + local[0], field.brick_coords[3 * b + 1] * 4 + local[1],
                            field.brick_coords[3 * b + 2] * 4 + local[2]};
        constexpr int kStride[3] = {1, 4, 16};
        float gd = 0.0f;
        float gc[kNerfColorCoeffs] = {};
        const float own = std::max(field.density[s], -10.0f);
        const float* own_c = &field.color[size_t(s) * kNerfColorCoeffs];
        for (int axis = 0; axis < 3; ++axis)
          for (int delta = -1; delta <= 1; delta += 2) {
            int32_t t;
            if (local[axis] + delta >= 0 && local[axis] + delta < kNerfBrickSide) {
              t = s + delta * kStride[axis];  // inside the same brick
            } else {
              int q[3] = {ijk[0], ijk[1], ijk[2]};
              q[axis] += delta;
              t = field.Slot(q[0], q[1], q[2]);
            }
            if (t < 0) continue;
            gd += own - std::max(field.density[t], -10.0f);
            const float* other = &field.color[size_t(t) * kNerfColorCoeffs];
            for (int m = 0; m < kNerfColorCoeffs; ++m) gc[m] += own_c[m] - other[m];
          }
        g_density[s] += tv_d * gd;
        float* g = &g_color[size_t(s) * kNerfColorCoeffs];
        for (int m = 0; m < kNerfColorCoeffs; ++m) g[m] += tv_c * gc[m];
      },
      1024);
}

// One Adam step (β1 0.9, β2 0.99) of every touched vertex; its gradient and mark are cleared.
void NerfTrainer::State::AdamUpdate(float lr_density, float lr_color) {
  const float b1 = 0.9f, b2 = 0.99f;
  const float c1 = 1.0f / (1.0f - std::pow(b1, float(adam_t))), c2 = 1.0f / (1.0f - std::pow(b2, float(adam_t)));
  const float step_d = lr_density * c1, step_c = lr_color * c1;
  const float slope_keep = 1.0f - lr_color * float(options.color_slope_decay);  // decoupled slope decay
  ParallelFor(
      all_touched.size(),
      [&](size_t n) {
        const int32_t s = all_touched[n];
        const float gd = g_density[s];
        float& md = m_density[s];
        float& vd = v_density[s];
        md = b1 * md + (1 - b1) * gd;
        vd = b2 * vd + (1 - b2) * gd * gd;
        field.density[s] = std::clamp(field.density[s] - step_d * md / (std::sqrt(vd * c2) + 1e-8f), kNerfDensityRawMin,
                                      kNerfDensityRawMax);
        g_density[s] = 0.0f;
        touched[s] = 0;
        const size_t base = size_t(s) * kNerfColorCoeffs;
        float* value = &field.color[base];
        float* mc = &m_color[base];
        float* vc = &v_color[base];
        float* gc = &g_color[base];
        for (int m = 0; m < kNerfColorCoeffs; ++m) {
          mc[m] = b1 * mc[m] + (1 - b1) * gc[m];
          vc[m] = b2 * vc[m] + (1 - b2) * gc[m] * gc[m];
          value[m] -= step_c * mc[m] / (std::sqrt(vc[m] * c2) + 1e-8f);
          gc[m] = 0.0f;
        }
        for (int ch = 0; ch < 3; ++ch) {
          value[4 * ch] = std::clamp(value[4 * ch], kNerfLogColorMin, kNerfLogColorMax);
          for (int m = 1; m < 4; ++m) value[4 * ch + m] = std::clamp(value[4 * ch + m] * slope_keep, -10.0f, 10.0f);
        }
      },
      1024);
}

// Pruning by weight every prune_every Adam steps (it rebuilds the occupancy); otherwise the
// occupancy every occupancy_every steps, at the finer levels only once the prune delay has passed.
void NerfTrainer::State::UpdateOccupancyOnSchedule() {
  if (options.prune_weight > 0 && adam_t >= options.prune_every && adam_t % options.prune_every == 0) {
    PruneByWeight();
    field.UpdateOccupancy(OccupancySigma());
  } else if (step % options.occupancy_every == 0 && (level == 0 || adam_t > options.prune_delay)) {
    field.UpdateOccupancy(OccupancySigma());
  }
}

// The verbose log of the last 50 steps: seconds per phase, samples per ray, vertices updated.
void NerfTrainer::State::LogPhaseTimes() {
  char text[256];
  std::snprintf(text, sizeof text,
                "nerf CPU time steps %d-%d level %d: march %.2f s, scatter %.2f s, adam %.2f s, occupancy %.2f s; "
                "%.1f samples/ray; %.0f vertices updated/step; %.2f %% cells occupied",
                step - 49, step, level, time_march, time_scatter, time_adam, time_occupancy,
                double(samples_marched) / double(std::max<uint64_t>(rays_marched, 1)), double(vertices_updated) / 50.0,
                100.0 * field.OccupiedFraction());
  LogVerbose(text);
  std::snprintf(text, sizeof text,
                "nerf wall time of the same steps: march %.2f s, scatter %.2f s, adam %.2f s, occupancy %.2f s",
                wall_march, wall_scatter, wall_adam, wall_occupancy);
  LogVerbose(text);
  time_march = time_scatter = time_adam = time_occupancy = 0;
  wall_march = wall_scatter = wall_adam = wall_occupancy = 0;
  samples_marched = rays_marched = vertices_updated = 0;
}

void NerfTrainer::State::PruneByWeight() {
  const float raw_threshold = std::log(std::max(OccupancySigma(), 1e-30f));
  const float w_min = float(options.prune_weight);
  // Measurement for the log: vertices above the occupancy threshold by their max weight.
  constexpr int kBins = 6;
  const float edges[kBins - 1] = {1e-4f, 1e-3f, 1e-2f, 3e-2f, 1e-1f};
  size_t bins[kBins] = {}, pruned = 0;
  for (size_t s = 0; s < field.SlotCount(); ++s) {
    float& d = field.density[s];
    const float w = max_weight[s];
    if (d > raw_threshold) {
      int b = 0;
      while (b < kBins - 1 && w >= edges[b]) ++b;
      ++bins[b];
    }
    if (w < w_min && d > kNerfPrunedDensityRaw) {
      if (d > raw_threshold) ++pruned;
      d = kNerfPrunedDensityRaw;
      m_density[s] = 0.0f;
      v_density[s] = 0.0f;
    }
    max_weight[s] = 0.0f;
  }
  std::string text =
      "nerf prune step " + std::to_string(step) + " level " + std::to_string(level) +
      ": vertices above the occupancy threshold by max weight [<1e-4, <1e-3, <1e-2, <3e-2, <0.1, >=0.1]:";
  for (size_t b : bins) text += " " + std::to_string(b);
  text += "; emptied " + std::to_string(pruned);
  LogVerbose(text);
}

NerfTrainer::NerfTrainer(const NerfTrainData& data, const NerfTrainOptions& options)
    : state_(std::make_unique<State>(data)) {
  State& s = *state_;
  s.options = options;
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) {
    Problems list("NeRF training options");
    for (const std::string& p : problems) list.Add("", p);
    list.ThrowIfAny();
  }
  if (data.train.empty()) throw InputError("NeRF training: no training views");
  s.pixel_offsets.push_back(0);
  std::vector<float> scales;
  double sum = 0, count = 0;
  for (const NerfView& v : data.train) {
    NERFAR_CHECK_EQ(v.rgb.channels, 3);
    NERFAR_CHECK_EQ(v.rgb.width, v.camera.width);
    NERFAR_CHECK_EQ(v.rgb.height, v.camera.height);
    s.pixel_offsets.push_back(s.pixel_offsets.back() + v.rgb.PixelCount());
    const float k = ExposureForPercentile(v.rgb, 0.99);
    if (std::isfinite(k) && k > 0) scales.push_back(1.0f / k);
    for (size_t n = 0; n < v.rgb.PixelCount(); ++n) {
      const float l = Luminance(&v.rgb.pixels[3 * n], 3);
      if (l > 0) sum += l, count += 1;
    }
  }
  std::sort(scales.begin(), scales.end());
  const double p99 = scales.empty() ? 1.0 : scales[scales.size() / 2];
  s.epsilon = options.loss_epsilon * (p99 > 0 ? p99 : 1.0);
  const double mean = count > 0 ? sum / count : 0.1;
  const float log_mean = float(std::log(std::max(mean, 1e-6)));
  s.field = NerfField::Dense(data.aabb, options.coarse_voxel_m, float(std::log(options.initial_sigma)),
                             Vec3f(log_mean, log_mean, log_mean));
  s.field.occupancy_sigma = s.OccupancySigma();
  s.ResetOptimiser();
}

NerfTrainer::~NerfTrainer() = default;

double NerfTrainer::Step() { return state_->DoStep(); }
bool NerfTrainer::Done() const { return state_->Progress() >= 1.0; }
int NerfTrainer::step() const { return state_->step; }
int NerfTrainer::level() const { return state_->level; }
double NerfTrainer::progress() const { return state_->Progress(); }
double NerfTrainer::elapsed_seconds() const { return state_->Elapsed(); }
const NerfField& NerfTrainer::field() const { return state_->field; }

double NerfTrainer::HeldOutPsnr(int max_views) const {
  const State& s = *state_;
  const size_t n = max_views > 0 ? std::min<size_t>(size_t(max_views), s.data.held_out.size()) : s.data.held_out.size();
  if (n == 0) return std::nan("");
  NerfRenderOptions render;
  render.step_voxels = float(s.options.step_voxels);
  double sum = 0;
  for (size_t v = 0; v < n; ++v) {
    const NerfView& view = s.data.held_out[v];
    sum += PsnrTm(RenderView(s.field, view.camera, view.T_world_camera, render).color, view.rgb);
  }
  return sum / double(n);
}

NerfField NerfTrainer::FinalField() const {
  NerfField f = state_->field;
  const double save_sigma = state_->options.save_occupancy_sigma;
  f.UpdateOccupancy(save_sigma > 0 ? float(save_sigma) : state_->OccupancySigma());
  for (const NerfView& view : state_->data.train) f.capture_centres.push_back(Vec3f(view.T_world_camera.translation));
  return f;
}

// ------------------------------------------------------------ checkpoints

// The checkpoint: the sectioned container of calib/core/binary_file.h ("NERFCKPT", version kNerfCheckpointVersion) with
// the sections IDEN, the identity (options JSON, dataset) as u64-length strings, and TRAN, the
// training state: step, level, Adam step, seconds trained, the grid, and the field's and
// optimiser's arrays, each a u64 count and its values. Checkpoints written before the container had
// sections ("NERFCKP2", version 2 in the magic) are flat: the identity and the state in that order
// and the legacy checksum; they are read too.
namespace {
constexpr BinaryFormat kCheckpointFormat{"nerfar training checkpoint", "NERFCKPT", true, 3, kNerfCheckpointVersion, 3,
                                         "delete it to start over"};
constexpr BinaryFormat kFlatCheckpointFormat{"nerfar training checkpoint", "NERFCKP2", false, 0, 0, 0,
                                             "delete it to start over"};
constexpr size_t kMaxCheckpointBytes = size_t{16} << 30;

template <typename T>
void PutVec(ByteWriter& w, const std::vector<T>& v) {
  w.Put(uint64_t(v.size()));
  w.PutArray(v);
}
void PutString(ByteWriter& w, const std::string& s) {
  w.Put(uint64_t(s.size()));
  w.PutBytes(s);
}

// An array of `expected` values (the grid read before says how many).
template <typename T>
std::vector<T> GetVec(ByteReader& r, uint64_t expected, const char* what) {
  const uint64_t n = r.Get<uint64_t>(what);
  if (n != expected)
    r.Fail("checkpoint's " + std::string(what) + " has " + std::to_string(n) + " values (expected " +
           std::to_string(expected) + ")");
  return r.GetArray<T>(n, what);
}
std::string GetString(ByteReader& r, const char* what) {
  const uint64_t n = r.Get<uint64_t>(what);
  return std::string(r.Take(n, what));
}
}  // namespace

void NerfTrainer::SaveCheckpoint(const std::string& path) const {
  const State& s = *state_;
  BinaryFileWriter w(kCheckpointFormat, kNerfCheckpointVersion);
  NerfTrainOptions identity = s.options;
  identity.max_seconds = 0;           // a resumed run may have another time budget
  identity.save_occupancy_sigma = 0;  // applies to the saved model only
  ByteWriter& iden = w.Section("IDEN");
  PutString(iden, identity.ToJson());
  PutString(iden, s.data.source + " " + std::to_string(s.data.train.size()));
  ByteWriter& tran = w.Section("TRAN");
  tran.Put(int32_t(s.step));
  tran.Put(int32_t(s.level));
  tran.Put(int32_t(s.adam_t));
  tran.Put(s.Elapsed());
  const NerfField& f = s.field;
  tran.Put(f.voxel_m);
  for (int a = 0; a < 3; ++a) tran.Put(int32_t(f.res[a]));
  PutVec(tran, f.brick_coords);
  PutVec(tran, f.density);
  PutVec(tran, f.color);
  PutVec(tran, f.occupancy);
  PutVec(tran, s.m_density);
  PutVec(tran, s.v_density);
  PutVec(tran, s.m_color);
  PutVec(tran, s.v_color);
  PutVec(tran, s.max_weight);
  WriteBinaryFile(path, std::move(w));
}

namespace {

// The options matched, so the checkpoint's grid must be the one this trainer has at its level:
// the coarse voxel halved per level over the dataset's box. Checked before the brick table is
// allocated, so a corrupt size cannot ask for more memory than training itself would use.
void CheckGridOfLevel(const NerfField& f, int level, const NerfTrainOptions& options, const std::string& path) {
  if (level < 0 || level >= options.levels)
    ThrowInputError(path, "checkpoint level " + std::to_string(level) + " (expected 0 to " +
                              std::to_string(options.levels - 1) + ")");
  const double voxel = options.coarse_voxel_m / double(1 << level);
  if (!(std::abs(f.voxel_m - voxel) <= 1e-5 * voxel))
    ThrowInputError(path, "checkpoint voxel size " + std::to_string(f.voxel_m) + " m at level " +
                              std::to_string(level) + " (expected " + std::to_string(voxel) + ")");
  for (int a = 0; a < 3; ++a) {
    // The grid spans the box with a vertex on each face: extent / voxel + 1, to within rounding.
    const double expected = (f.aabb.max[a] - f.aabb.min[a]) / voxel + 1;
    if (!(std::abs(f.res[a] - expected) <= 2))
      ThrowInputError(path, "checkpoint grid resolution " + std::to_string(f.res[a]) + " (expected about " +
                                std::to_string(int(std::lround(expected))) + " at level " + std::to_string(level) +
                                ")");
  }
}

}  // namespace

void NerfTrainer::LoadCheckpoint(const std::string& path) {
  State& s = *state_;
  const std::string bytes = ReadFileBytes(path, kMaxCheckpointBytes);
  const bool flat = std::string_view(bytes).substr(0, 8) == kFlatCheckpointFormat.magic;
  const BinaryFile file = OpenBinaryFile(bytes, path, flat ? kFlatCheckpointFormat : kCheckpointFormat);
  // A flat file holds the identity and the state in one run of fields.
  ByteReader iden = flat ? file.fields : file.Section("IDEN");
  NerfTrainOptions identity = s.options;
  identity.max_seconds = 0;
  identity.save_occupancy_sigma = 0;
  if (GetString(iden, "options") != identity.ToJson())
    ThrowInputError(path,
                    "checkpoint was made with other training options (use the same preset and --set, or delete it)");
  if (GetString(iden, "dataset") != s.data.source + " " + std::to_string(s.data.train.size()))
    ThrowInputError(path, "checkpoint was made from another dataset (delete it to start over)");
  if (!flat) iden.ExpectEnd("the identity");
  ByteReader r = flat ? iden : file.Section("TRAN");
  const int step = r.Get<int32_t>("step"), level = r.Get<int32_t>("level"), adam_t = r.Get<int32_t>("Adam step");
  const double elapsed = r.Get<double>("seconds trained");
  NerfField f;
  f.aabb = s.data.aabb;
  f.origin = Vec3f(s.data.aabb.min);
  f.voxel_m = r.Get<float>("voxel size");
  for (int a = 0; a < 3; ++a) f.res[a] = r.Get<int32_t>("resolution");
  CheckGridOfLevel(f, level, s.options, path);
  for (int a = 0; a < 3; ++a) f.bricks[a] = (f.res[a] + 3) / 4;
  const uint64_t n_coords = r.Get<uint64_t>("brick list");
  if (n_coords % 3 != 0 || n_coords / 3 > size_t(f.bricks[0]) * f.bricks[1] * f.bricks[2])
    ThrowInputError(path, "checkpoint brick list is inconsistent");
  std::vector<int32_t> values = r.GetArray<int32_t>(n_coords, "brick list");
  f.brick_table.assign(size_t(f.bricks[0]) * f.bricks[1] * f.bricks[2], -1);
  for (uint64_t b = 0; b < n_coords / 3; ++b) {
    const int x = values[3 * b], y = values[3 * b + 1], z = values[3 * b + 2];
    if (x < 0 || y < 0 || z < 0 || x >= f.bricks[0] || y >= f.bricks[1] || z >= f.bricks[2])
      ThrowInputError(path, "checkpoint brick outside the grid");
    if (f.brick_table[(size_t(z) * f.bricks[1] + y) * f.bricks[0] + x] >= 0)
      ThrowInputError(path, "checkpoint brick listed twice");
    f.brick_table[(size_t(z) * f.bricks[1] + y) * f.bricks[0] + x] = int32_t(b);
  }
  f.brick_coords = std::move(values);
  const uint64_t slots = n_coords / 3 * kNerfBrickSlots;
  f.density = GetVec<float>(r, slots, "density");
  f.color = GetVec<float>(r, slots * kNerfColorCoeffs, "colour");
  f.occupancy = GetVec<uint64_t>(r, n_coords / 3, "occupancy");
  s.m_density = GetVec<float>(r, slots, "density moment 1");
  s.v_density = GetVec<float>(r, slots, "density moment 2");
  s.m_color = GetVec<float>(r, slots * kNerfColorCoeffs, "colour moment 1");
  s.v_color = GetVec<float>(r, slots * kNerfColorCoeffs, "colour moment 2");
  s.max_weight = GetVec<float>(r, slots, "sample weights");
  r.ExpectEnd("the training state");
  const std::vector<std::string> problems = f.Validate();
  if (!problems.empty()) ThrowInputError(path, "checkpoint field: " + problems.front());
  s.field = std::move(f);
  s.step = step;
  s.level = level;
  s.adam_t = adam_t;
  s.field.occupancy_sigma = s.OccupancySigma();
  s.elapsed_before = elapsed;
  s.start = std::chrono::steady_clock::now();
  s.g_density.assign(s.field.SlotCount(), 0.0f);
  s.g_color.assign(s.field.SlotCount() * kNerfColorCoeffs, 0.0f);
  s.touched.assign(s.field.SlotCount(), 0);
  s.adam_t = adam_t;
}

}  // namespace nerfar

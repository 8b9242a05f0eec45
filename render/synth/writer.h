// `nerfar synth`: renders a named procedural scene into the layout of
// ../shared/scenes/README.md (transforms*.json, train/ and test/ half EXRs,
// board.json, lights.json, env.exr, objects/, insert/ ground truth) plus a
// contact sheet PNG. Cameras lie on the upper hemisphere around the table
// centre (elevation 15-70 deg, distance 0.8-1.3 m, no roll), OpenCV axes in
// memory, OpenGL axes in the files (calib/dataset.h converts).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/image.h"
#include "calib/core/math.h"
#include "render/synth/scenes.h"

namespace nerfar::synth {

struct SynthOptions {
  std::string scene = "lamps";    // one of SynthSceneNames()
  std::string output_dir;         // created if missing; files inside are replaced atomically
  int width = 400, height = 300;  // image size; horizontal field of view 60 deg at any size
  int views = 100;                // training views
  int test_views = 8;             // test views (other poses), also the insert/ views
  int spp = 16;                   // samples per pixel of train/test views (noise ~ 1/sqrt(spp))
  int insert_spp = 64;            // samples per pixel of insert/ renders (bg and rgb)
  int probe_spp = 16;             // samples per probe pixel (256 x 128 panorama)
  uint64_t seed = 1;              // fixes the scene, the cameras and every random number
  bool bounce = false;            // one bounce of indirect light (about 2x the time)
  bool insert = true;             // write insert/ and objects/ (ground truth for insertion)
  int contact_sheet_views = 12;   // views tiled into contact_sheet.png (0: none)

  // Every problem, each "field: value (expected ...)"; empty when valid.
  std::vector<std::string> Validate() const;
  // Named presets of the sample counts: "fast" (4 / 16 / 4), "balanced"
  // (16 / 64 / 16, the defaults) and "accurate" (64 / 256 / 64). False if unknown.
  bool ApplyPreset(const std::string& name);
};

struct SynthReport {
  double seconds_total = 0;
  double seconds_train_test = 0;  // train + test views
  double seconds_insert = 0;      // insert/ renders and probes
  int images = 0;                 // EXR images written
};

// Pinhole camera of the synthetic scenes: 60 deg horizontal field of view,
// square pixels, principal point at the image centre, no distortion.
CameraIntrinsics SynthCamera(int width, int height);

// `count` camera poses (T_world_camera, OpenCV axes) on the upper hemisphere
// around the table centre, fixed by (seed, stream): azimuths spread by the
// golden angle, elevations stratified over 15-70 deg, distances 0.8-1.3 m,
// looking at a point within 3 cm of the table centre, no roll; every centre
// outside `aabb`.
std::vector<Pose> HemisphereCameras(int count, uint64_t seed, uint64_t stream, const Aabb& aabb);

// Tiles tone-mapped images (each exposed for its own 99th percentile) into a
// grid with `columns` columns.
Image8 ContactSheet(const std::vector<ImageF>& images, int columns);

// Writes the whole scene folder; logs progress with an ETA.
SynthReport WriteSynthDataset(const SynthOptions& options);

}  // namespace nerfar::synth

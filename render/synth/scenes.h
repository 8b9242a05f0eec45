// Named procedural tabletop scenes, fixed by (name, seed), in the world frame
// of ../shared/scenes/README.md: metres, z up, table top z = 0 spanning
// x in [-0.6, 0.6], y in [-0.4, 0.4], 0.04 m thick; an AprilTag mat (tag36h11
// ids 0..11 on white sheets 0.5 mm above the table, laid out like the shared
// scenes' board.json); Lambertian boxes, spheres and cylinders; lights; and
// two virtual objects to insert (a glossy sphere and a diffuse mesh).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "calib/board.h"
#include "calib/dataset.h"
#include "calib/object.h"
#include "render/mesh/mesh.h"
#include "render/synth/scene.h"

namespace nerfar::synth {

// Ink and paper albedo of the tag mat (README: matte, 0.03 and 0.80).
inline constexpr float kInkAlbedo = 0.03f;
inline constexpr float kPaperAlbedo = 0.80f;
inline constexpr double kTagSize = 0.06;      // outer black square, metres
inline constexpr double kTagMargin = 0.015;   // white margin around it, metres
inline constexpr double kTagSheetZ = 0.0005;  // sheet height above the table top

// The procedural sky of a hidden-light scene (lights.json describes it):
// L(d) = horizon + (zenith - horizon) sqrt(d_z) for d_z >= 0, ground below,
// replaced by `window_radiance` inside the window patch
// |azimuth - window_azimuth_deg| <= window_width_deg / 2,
// window_elev_min_deg <= elevation <= window_elev_max_deg.
struct SkyWithWindow {
  Vec3 zenith{0.10, 0.16, 0.30}, horizon{0.30, 0.32, 0.35}, ground{0.06, 0.05, 0.04};
  double window_azimuth_deg = 45, window_width_deg = 26, window_elev_min_deg = 22, window_elev_max_deg = 44;
  Vec3 window_radiance{38, 34, 28};
  Vec3 Radiance(const Vec3& d) const;
};

// A virtual object to insert: its mesh in the object frame (metres, +z up,
// origin at the bounding-box centre), material and placement on the table.
struct InsertObject {
  std::string name;  // e.g. "sphere_glossy": folder and file names in the output
  TriangleMesh mesh;
  Material material;
  ObjectPlacement placement;  // rotation about z and translation; lowest point at z = 0
};

struct SynthScene {
  std::string name;
  uint64_t seed = 0;
  Scene scene;  // everything but the inserted objects, built
  Board board;
  Aabb aabb{{-0.62, -0.42, -0.05}, {0.62, 0.42, 0.60}};  // NeRF volume (README)
  std::optional<SkyWithWindow> sky;                      // the window scene's environment
  std::vector<InsertObject> objects;
  std::string description;  // one line for lights.json / logs
};

// "lamps": a bulb (sphere light) on a pole and a front-emitting panel on a
//          pole, no environment (everything that lights the scene is visible).
// "window": hidden distant light only: a dim sky plus a bright window patch
//          (equirect map), and a small glowing cube as the one visible emitter.
// "sun":    a combination: an SG environment (sky lobe and a sharp sun lobe)
//          plus a bulb on a pole.
std::vector<std::string> SynthSceneNames();
// InputError naming the known scenes when `name` is unknown.
SynthScene MakeSynthScene(const std::string& name, uint64_t seed);

// The table with its tag mat alone (no objects, no lights), not built.
Scene MakeTabletop(uint64_t seed);

// The board of every synthetic scene (same layout as ../shared/scenes).
Board MakeTagBoard();

// The scene with object k inserted (its shapes tagged with object_id = k), built.
Scene SceneWithObject(const SynthScene& scene, int k);

}  // namespace nerfar::synth

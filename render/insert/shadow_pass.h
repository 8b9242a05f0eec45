// Internal to render/insert: the shadow pass of a frame — κ (paper eqs. 8-9)
// on the scene's receivers within reach of the casters, multiplied into the
// background where no object covers it — and what it keeps between frames.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "render/insert/cache_keys.h"
#include "render/insert/insert_common.h"
#include "render/insert/inserter.h"
#include "render/insert/kappa_lattice.h"
#include "render/insert/light_prep.h"
#include "render/insert/receivers.h"

namespace nerfar {

// The view a κ layer is made for: the camera's intrinsics and pose.
struct ViewKey {
  double fx = 0, fy = 0, cx = 0, cy = 0;  // pixels
  int width = 0, height = 0;              // pixels
  std::array<double, 9> rotation{};       // T_world_camera's rotation, row-major
  std::array<double, 3> translation{};    // T_world_camera's translation, metres
  bool operator==(const ViewKey&) const = default;
};

// A number no other lattice of this process has held (KappaCache::generation).
uint64_t NewKappaGeneration();

// What the shadow pass keeps between frames; `key` says which objects,
// lights and options the lattice and the last layer hold.
struct KappaCache {
  KappaKey key;
  // Which lattice the levels hold: new at every Clear (the threads' memos
  // of the lattice's values hold while it stays).
  uint64_t generation = NewKappaGeneration();
  // The lattice's nodes (and its shadow box) lie at world point node +
  // shift: 0, but through a drag (DragFrame::kappa_shift) the lattice is
  // kept in the objects' frame as κ's held light was taken.
  KappaLattice lattice;
  // Finer levels (spacing halved at each) where a sharp light's penumbra is
  // narrower than a cell of the level above; in the same frame.
  std::array<KappaLattice, kKappaFineLevels> fine;
  Vec3 shift;
  // Views whose whole reach rectangle was passed under the current key:
  // each visible receiver there has its nodes here.
  std::vector<ViewKey> explored;
  // The last frame's κ grid (nodes at pixel columns last_xs, rows
  // last_ys), its rectangle and its exact view (none after Clear).
  std::optional<ViewKey> last_view;
  PixelRect last_rect;
  std::vector<int> last_xs, last_ys;
  std::vector<float> last_grid;
  // The last frame's NeRF receivers (kept across Clear: they depend on the
  // scene and the opacity threshold only).
  ReceiverFrame receivers;
  // Receiver normals per world cell (InsertOptions::receiver_normal_per_cell),
  // kept across Clear while the spacing holds.
  CellNormals cell_normals;

  // Drops the lattice, the explored views and the last layer.
  void Clear() {
    generation = NewKappaGeneration();
    lattice.Clear();
    for (KappaLattice& level : fine) level.Clear();
    explored.clear();
    last_view.reset();
    last_grid.clear();
  }
  // Nodes in every level.
  size_t Size() {
    size_t n = lattice.Size();
    for (KappaLattice& level : fine) n += level.Size();
    return n;
  }
  // Every level's nodes of the last frame made readable without locks.
  void Publish() {
    lattice.Publish();
    for (KappaLattice& level : fine) level.Publish();
  }
};

// κ's grid in a frame `width` pixels wide: the step and the coarse factor
// (InsertOptions::kappa_step, kappa_coarse_factor, kappa_grid_width).
struct KappaSpacing {
  int step = 1;
  size_t factor = 1;
};
KappaSpacing KappaSpacingFor(const InsertOptions& options, int width);

// The frame's inputs to the shadow pass (loans for the call).
struct ShadowSources;
struct DragFrame;

struct ShadowPassInputs {
  const SceneField& scene;
  const InsertOptions& options;
  const CameraIntrinsics& camera;
  const Pose& T_world_camera;
  const std::vector<InsertObject>& objects;
  const std::vector<WorldSphere>& spheres;
  const std::vector<SgMixture>& lights;  // each object's light this frame
  const ObjectGBuffer& gbuffer;          // object pixels keep their composite
  const ReceiverOverride& receivers;
  const std::vector<ShadowSources>* sources = nullptr;  // per object, κ from samples (KappaContext::sources)
  const SupportPlane* support = nullptr;                // receivers ending on it are taken onto it
  const DragFrame* drag = nullptr;  // dragged: the lattice kept in the objects' frame (`lights`: κ's, DragFrame)
};

// κ over the casters' reach rectangle into layers.kappa / kappa_rect /
// kappa_queries and the background `frame` multiplied by it; `preps` (one per
// object) are prepared on demand; `cache` created on demand when the lattice
// is on (kappa_cache_spacing_radii > 0). Counters into `times`.
void RenderShadows(const ShadowPassInputs& in, std::vector<LightPrep>& preps, std::unique_ptr<KappaCache>& cache,
                   ImageF& frame, InsertLayers& layers, InsertTimings& times);

}  // namespace nerfar

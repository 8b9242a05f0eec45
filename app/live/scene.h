// A live SCENE: one folder holding what `nerfar live` needs, as `nerfar demo`
// writes it (and as a real session ends up after train, env and bake):
//   SCENE/scene.nerf (or the only *.nerf)      the trained HDR NeRF (required)
//   SCENE/env.json                             environment SGs (optional)
//   SCENE/board.json | SCENE/dataset/board.json     the AprilTag board
//   SCENE/camera.json | SCENE/dataset/transforms.json   the camera (optional:
//       --camera, or the synthetic stream's own intrinsics)
//   SCENE/*.ssdf                               objects (the default --object)
// Objects: an .ssdf (its mesh and material from the field, shadows on) or a
// bare mesh (no shadows); either with its material's textures. Folders called `scene` instead of `dataset` are
// accepted too (scripts/demo.sh's earlier layout).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/object_assets.h"
#include "calib/board.h"
#include "calib/camera_file.h"
#include "render/lighting/env_light.h"
#include "render/lighting/scene_field.h"
#include "render/mesh/mesh.h"
#include "render/nerf/nerf_field.h"
#include "render/sg/brdf.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

struct LiveScenePaths {
  std::string dir;
  std::string nerf, env, board, camera;  // "" where absent (nerf and board are required to load)
  std::vector<std::string> objects;      // SCENE/*.ssdf, sorted
};

// Finds the files of a SCENE folder (InputError when it is not a folder).
LiveScenePaths FindLiveScene(const std::string& dir);

struct LiveSceneData {
  LiveScenePaths paths;
  NerfField nerf;
  std::unique_ptr<SceneField> field;  // the NeRF as insertion queries it (LivePipeline sets its options)
  EnvLight env;                       // lobes empty when absent or negligible
  std::optional<Board> board;
  std::optional<CameraFile> camera;
};

// Loads the NeRF, env and, where found, board and camera; InputError listing
// what is missing or wrong.
LiveSceneData LoadLiveScene(const LiveScenePaths& paths);

struct LiveObjectAsset {
  std::string name, path;
  TriangleMesh mesh;
  std::optional<SsdfField> field;
  SgMaterial material;
  MaterialMaps maps;  // its textures, which override the material's constants where given
};

// An object from an .ssdf (mesh resolved beside it) or a mesh file.
LiveObjectAsset LoadLiveObject(const std::string& path);

}  // namespace nerfar

#include "app/live/scene.h"

#include <algorithm>
#include <filesystem>

#include "app/object_assets.h"
#include "calib/core/error.h"
#include "calib/core/log.h"
#include "render/insert/nerf_scene.h"
#include "render/nerf/nerf_file.h"

namespace nerfar {

namespace fs = std::filesystem;

namespace {

std::string FirstExisting(const std::vector<fs::path>& candidates) {
  std::error_code error;
  for (const fs::path& p : candidates)
    if (fs::is_regular_file(p, error)) return p.string();
  return {};
}

}  // namespace

LiveScenePaths FindLiveScene(const std::string& dir) {
  std::error_code error;
  if (!fs::is_directory(dir, error))
    ThrowInputError(dir, "not a folder (expected a SCENE folder with scene.nerf, board.json, ...)");
  LiveScenePaths paths;
  paths.dir = dir;
  const fs::path d(dir);
  std::vector<std::string> nerfs;
  for (const auto& entry : fs::directory_iterator(d, error)) {
    const fs::path& p = entry.path();
    if (p.extension() == ".nerf") nerfs.push_back(p.string());
    if (p.extension() == ".ssdf") paths.objects.push_back(p.string());
  }
  std::sort(nerfs.begin(), nerfs.end());
  std::sort(paths.objects.begin(), paths.objects.end());
  paths.nerf = FirstExisting({d / "scene.nerf"});
  if (paths.nerf.empty() && nerfs.size() == 1) paths.nerf = nerfs[0];
  paths.env = FirstExisting({d / "env.json"});
  paths.board = FirstExisting({d / "board.json", d / "dataset" / "board.json", d / "scene" / "board.json"});
  paths.camera = FirstExisting({d / "camera.json", d / "dataset" / "transforms.json", d / "scene" / "transforms.json",
                                d / "dataset" / "transforms_train.json"});
  return paths;
}

LiveSceneData LoadLiveScene(const LiveScenePaths& paths) {
  Problems problems(paths.dir);
  if (paths.nerf.empty())
    problems.Add("scene.nerf", "missing (expected the trained NeRF: `nerfar train ... -o SCENE/scene.nerf`)");
  problems.ThrowIfAny();
  LiveSceneData data;
  data.paths = paths;
  data.nerf = LoadNerf(paths.nerf);
  data.nerf.UpdateRenderCopy();  // the field does not change from here on: rays read its compact copy
  data.field = std::make_unique<NerfScene>(data.nerf);
  if (!paths.env.empty()) {
    data.env = ReadEnvLight(paths.env);
    if (DropIfNegligible(data.env))
      LogInfo("live: " + paths.env + " marks the environment as negligible: it is dropped");
  }
  if (!paths.board.empty()) data.board = ReadBoard(paths.board);
  if (!paths.camera.empty()) data.camera = ReadCameraFile(paths.camera);
  return data;
}

LiveObjectAsset LoadLiveObject(const std::string& path) {
  LiveObjectAsset asset;
  asset.path = path;
  asset.name = fs::path(path).stem().string();
  std::optional<Material> material;
  if (fs::path(path).extension() == ".ssdf") {
    asset.field = ReadSsdf(path);
    if (asset.field->mesh_reference.empty())
      ThrowInputError(path, "names no mesh (expected a field baked from a mesh)");
    const std::string mesh = FindBeside(asset.field->mesh_reference, path);
    if (mesh.empty())
      ThrowInputError(path,
                      "its mesh '" + asset.field->mesh_reference + "' was not found (expected it beside the file)");
    asset.mesh = ReadMesh(mesh);
    material = asset.field->material;
  } else {
    asset.mesh = ReadMesh(path);
  }
  if (!material) material = asset.mesh.material;
  if (material) {
    asset.material.base_color = material->albedo;
    asset.material.roughness = material->roughness;
    asset.material.metallic = material->metallic;
    asset.maps = LoadMaterialMaps(*material, path);
  }
  return asset;
}

}  // namespace nerfar

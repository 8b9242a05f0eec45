#include "app/command_files.h"

#include <cstdio>
#include <filesystem>

namespace nerfar {
namespace fs = std::filesystem;

PathList SourceInputs(const std::string& source) {
  for (const char* scheme : {"video:", "images:"})
    if (source.rfind(scheme, 0) == 0) return {source.substr(std::string(scheme).size())};
  std::error_code error;
  if (source.rfind("/dev/", 0) != 0 && fs::exists(source, error)) return {source};
  return {};
}

PathList DatasetInputs(const Dataset& dataset) {
  PathList paths = {dataset.path};
  for (const DatasetFrame& frame : dataset.frames) paths.push_back(frame.image_path);
  return paths;
}

PathList DatasetFolderInputs(const std::string& dir) {
  PathList paths;
  for (const char* split : {"train", "test", "val"}) {
    const std::string path = DatasetSplitPath(dir, split);
    std::error_code error;
    if (fs::is_regular_file(path, error)) {
      const PathList split_paths = DatasetInputs(ReadDataset(path));
      paths.insert(paths.end(), split_paths.begin(), split_paths.end());
    }
  }
  return paths;
}

PathList InsertOutputs(const std::string& folder, const Dataset& dataset, size_t objects) {
  PathList names = {"probe.exr",    "probe_samples.exr", "probe_opacity.exr",
                    "options.json", "timings.json",      "report.json"};
  for (size_t i = 1; i < objects; ++i) names.push_back("probe_" + std::to_string(i) + ".exr");
  for (const DatasetFrame& frame : dataset.frames) {
    const std::string stem = fs::path(frame.image_path).stem().string();
    for (const char* suffix : {".exr", ".png", "_object.exr", "_alpha.exr", "_kappa.exr", "_sheet.png"})
      names.push_back(stem + suffix);
  }
  return FilesIn(folder, names);
}

std::string VideoFrameName(size_t i) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%04zu", i);
  return name;
}

PathList VideoOutputs(const std::string& folder, size_t views, size_t objects) {
  PathList names = {"video.mp4", "probe.exr", "options.json", "timings.json"};
  for (size_t i = 1; i < objects; ++i) names.push_back("probe_" + std::to_string(i) + ".exr");
  for (size_t i = 0; i < views; ++i) names.push_back(VideoFrameName(i) + ".png");
  return FilesIn(folder, names);
}

PathList InsertTruthInputs(const std::string& truth_dir) {
  if (truth_dir.empty()) return {};
  const fs::path parent = fs::absolute(truth_dir).lexically_normal().parent_path();
  return {truth_dir, parent.string()};
}

PathList RenderOutputs(const std::string& folder, const Dataset& dataset) {
  PathList names = {"report.json"};
  for (const DatasetFrame& frame : dataset.frames) {
    const std::string stem = fs::path(frame.file_path).stem().string();
    for (const char* suffix : {".exr", "_depth.exr", "_surface_depth.exr", "_opacity.exr", ".png"})
      names.push_back(stem + suffix);
  }
  return FilesIn(folder, names);
}

PathList RenderReferenceInputs(const std::string& dataset_dir) {
  const fs::path insert = fs::path(dataset_dir) / "insert";
  PathList paths = {insert.string()};
  std::error_code error;
  if (fs::is_directory(insert, error))
    for (const fs::directory_entry& entry : fs::directory_iterator(insert, error))
      if (entry.is_directory(error)) paths.push_back(entry.path().string());
  return paths;
}

PathList CaptureOutputs(const std::string& folder, int views) {
  PathList names = {"transforms_train.json", "transforms.json", "transforms_test.json", "capture_log.json"};
  for (int i = 0; i < views; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "r_%03d.exr", i);
    names.push_back(std::string("train/") + name);
    names.push_back(std::string("test/") + name);
  }
  return FilesIn(folder, names);
}

PathList LiveSessionOutputs(const std::string& session_dir) {
  return FilesIn(session_dir, {"session.json", "report.json", "report.png", "report.html", "last_ar.png",
                               "last_alongside.png", "last_layers.png", "recording.mp4"});
}

}  // namespace nerfar

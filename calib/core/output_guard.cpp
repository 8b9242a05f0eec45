#include "calib/core/output_guard.h"

#include <sys/stat.h>

#include <filesystem>
#include <map>
#include <utility>

#include "calib/core/error.h"

namespace nerfar {
namespace fs = std::filesystem;

namespace {

// Absolute, links and dot segments resolved as far as the path exists.
std::string Resolved(const std::string& path) {
  std::error_code error;
  const fs::path absolute = fs::absolute(path, error);
  if (error) return path;
  const fs::path resolved = fs::weakly_canonical(absolute, error);
  return error ? absolute.lexically_normal().string() : resolved.string();
}

// Device and inode of an existing file (following links).
bool FileIdentity(const std::string& path, std::pair<dev_t, ino_t>& id) {
  struct stat status {};
  if (::stat(path.c_str(), &status) != 0) return false;
  id = {status.st_dev, status.st_ino};
  return true;
}

// The input files: folders stand for the files directly in them.
std::vector<std::string> ExpandInputs(const std::vector<std::string>& inputs) {
  std::vector<std::string> files;
  for (const std::string& input : inputs) {
    if (input.empty()) continue;
    std::error_code error;
    if (!fs::is_directory(input, error)) {
      files.push_back(input);
      continue;
    }
    for (const fs::directory_entry& entry : fs::directory_iterator(input, error))
      if (entry.is_regular_file(error)) files.push_back(entry.path().string());
  }
  return files;
}

}  // namespace

std::vector<std::string> FilesIn(const std::string& folder, const std::vector<std::string>& names) {
  std::vector<std::string> paths;
  paths.reserve(names.size());
  for (const std::string& name : names) paths.push_back((fs::path(folder) / name).string());
  return paths;
}

void CheckOutputsSpareInputs(const std::vector<std::string>& outputs, const std::vector<std::string>& inputs) {
  // Each path is resolved once: commands list thousands of frames.
  std::map<std::string, std::string> by_path;
  std::map<std::pair<dev_t, ino_t>, std::string> by_identity;
  for (const std::string& input : ExpandInputs(inputs)) {
    by_path.emplace(Resolved(input), input);
    std::pair<dev_t, ino_t> id;
    if (FileIdentity(input, id)) by_identity.emplace(id, input);
  }
  std::map<std::string, std::string> written;
  for (const std::string& output : outputs) {
    if (output.empty()) continue;
    const std::string resolved = Resolved(output);
    if (const auto [it, added] = written.emplace(resolved, output); !added)
      ThrowInputError(output, "is given for two outputs (also as " + it->second + "; expected distinct files)");
    const std::string* input = nullptr;
    if (const auto it = by_path.find(resolved); it != by_path.end()) input = &it->second;
    std::pair<dev_t, ino_t> id;
    if (input == nullptr && FileIdentity(output, id))
      if (const auto it = by_identity.find(id); it != by_identity.end()) input = &it->second;
    if (input != nullptr)
      ThrowInputError(output, "would overwrite the input " + *input +
                                  " (expected an output that is none of the command's inputs; choose another)");
  }
}

}  // namespace nerfar

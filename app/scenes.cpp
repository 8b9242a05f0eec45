#include "app/scenes.h"

#include <cstdlib>
#include <filesystem>

namespace nerfar {

std::string FindSharedScenes() {
  namespace fs = std::filesystem;
  std::error_code error;
  const auto usable = [&](const fs::path& p) { return fs::is_regular_file(p / "README.md", error); };
  if (const char* env = std::getenv("NERFAR_SCENES"); env != nullptr && *env) return usable(env) ? env : "";
  for (const fs::path& base : {fs::path(NERFAR_SOURCE_DIR), fs::current_path(error)}) {
    const fs::path candidate = base.parent_path() / "shared" / "scenes";
    if (usable(candidate)) return fs::weakly_canonical(candidate, error).string();
    if (usable(base / "../shared/scenes")) return fs::weakly_canonical(base / "../shared/scenes", error).string();
  }
  return "";
}

}  // namespace nerfar

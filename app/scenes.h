// Where the shared HDR scenes (../shared/scenes) are: $NERFAR_SCENES if set,
// else ../shared/scenes beside the source tree or the working directory.
// Empty when absent: callers then skip with a message.
#pragma once

#include <string>

namespace nerfar {
std::string FindSharedScenes();
}

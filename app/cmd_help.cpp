#include <cstdio>
#include <string>

#include "app/commands.h"
#include "calib/core/error.h"

namespace nerfar {

int RunHelp(const CommandArgs& args) {
  if (!args.empty()) {
    for (const Command& command : AllCommands()) {
      if (args[0] == command.name) return command.run({"--help"});
    }
    throw InputError("nerfar help: unknown command '" + args[0] + "'");
  }
  std::printf(
      "nerfar: put virtual objects into captured real scenes, live.\n\n"
      "usage: nerfar COMMAND [arguments] [options]   (nerfar COMMAND --help for details)\n\n"
      "commands:\n");
  for (const Command& command : AllCommands()) {
    std::string name = "  " + std::string(command.name);
    name.resize(14, ' ');
    std::printf("%s%s\n", name.c_str(), command.summary);
  }
  std::printf("\ncommon options: --threads N, --quiet, --verbose, --help\n");
  return 0;
}

int RunVersion(const CommandArgs& args) {
  if (!args.empty() && args[0] == "--help") {
    std::printf("usage: nerfar version\n\nprint the version and the libraries it was built with\n");
    return 0;
  }
  std::printf("nerfar %s (C++20, %s)\n", NERFAR_VERSION, NERFAR_BUILD_TYPE);
  return 0;
}

}  // namespace nerfar

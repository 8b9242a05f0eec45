// nerfar: git-style subcommands. Maps the two kinds of failure (error.h) to
// exit codes 2 (bad usage or input) and 1 (run time), makes sure nothing
// escapes as a crash, and ends cleanly on SIGINT / SIGTERM (app/stop_signal.h).
#include <cstdio>
#include <exception>
#include <new>
#include <string>

#include "app/commands.h"
#include "app/stop_signal.h"
#include "calib/core/error.h"

int main(int argc, char** argv) {
  using namespace nerfar;
  InstallStopHandlers();
  const std::string command = argc > 1 ? argv[1] : "help";
  const CommandArgs args(argv + (argc > 1 ? 2 : argc), argv + argc);
  for (const Command& entry : AllCommands()) {
    if (command != entry.name) continue;
    try {
      return entry.run(args);
    } catch (const InputError& e) {
      std::fprintf(stderr, "error: %s\n", e.what());
      return 2;
    } catch (const std::bad_alloc&) {
      std::fprintf(stderr, "error: out of memory in 'nerfar %s'\n", entry.name);
      return 1;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "error: %s\n", e.what());
      return 1;
    }
  }
  if (command == "--help" || command == "-h") return RunHelp({});
  if (command == "--version") return RunVersion({});
  std::fprintf(stderr, "error: nerfar: unknown command '%s' (see 'nerfar help')\n", command.c_str());
  return 2;
}

// The `nerfar` subcommands. Each lives in its own app/cmd_NAME.cpp and is
// listed once in commands.cpp. A command returns its exit code: 0 ok,
// 1 failure at run time, 2 bad usage or bad input (DESIGN.md); InputError
// thrown from a command maps to 2, anything else to 1.
#pragma once

#include <string>
#include <vector>

namespace nerfar {

using CommandArgs = std::vector<std::string>;

struct Command {
  const char* name;
  const char* summary;
  int (*run)(const CommandArgs& args);
};

const std::vector<Command>& AllCommands();

// One declaration per subcommand.
int RunHelp(const CommandArgs& args);
int RunVersion(const CommandArgs& args);
int RunBench(const CommandArgs& args);
int RunEnv(const CommandArgs& args);
int RunInsert(const CommandArgs& args);
int RunBake(const CommandArgs& args);
int RunBoard(const CommandArgs& args);
int RunCalibrate(const CommandArgs& args);
int RunCapture(const CommandArgs& args);
int RunSynth(const CommandArgs& args);
int RunImport(const CommandArgs& args);
int RunTrain(const CommandArgs& args);
int RunRender(const CommandArgs& args);
int RunTrack(const CommandArgs& args);
int RunCameras(const CommandArgs& args);
int RunLive(const CommandArgs& args);
int RunDemo(const CommandArgs& args);
int RunReport(const CommandArgs& args);

}  // namespace nerfar

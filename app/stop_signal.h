// SIGINT (Ctrl-C) and SIGTERM (a closed session, a service manager) for every
// command. main() installs the handlers once. By default a signal removes the
// temporary files of the writes in progress (calib/core/atomic_file.h) and
// ends the process at once with exit code 128 + the signal's number (130 for
// SIGINT, 143 for SIGTERM): nothing half-written is left and every finished
// file is whole. A command that has something to save (a training
// checkpoint, a capture's or a live session's files) holds a StopScope over
// its loop: a signal then only marks StopRequested(); the command ends its
// current step, writes what it must and returns StopExitCode(). A second
// signal ends it at once, as without the scope.
#pragma once

namespace nerfar {

void InstallStopHandlers();

// While one is alive, SIGINT / SIGTERM are deferred to the command (nestable).
class StopScope {
 public:
  StopScope();
  ~StopScope();
  StopScope(const StopScope&) = delete;
  StopScope& operator=(const StopScope&) = delete;
};

// True once a signal arrived inside a StopScope.
bool StopRequested();
// 128 + the number of that signal; 0 when none arrived.
int StopExitCode();

}  // namespace nerfar

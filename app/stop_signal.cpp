#include "app/stop_signal.h"

#include <unistd.h>

#include <atomic>
#include <csignal>

#include "calib/core/atomic_file.h"

namespace nerfar {
namespace {

std::atomic<int> g_scopes{0};  // StopScopes alive
std::atomic<int> g_signal{0};  // the deferred signal's number (0: none)

extern "C" void OnStopSignal(int number) {
  int none = 0;
  if (g_scopes.load() > 0 && g_signal.compare_exchange_strong(none, number)) return;
  RemoveTemporaryFiles();
  ::_exit(128 + number);
}

}  // namespace

void InstallStopHandlers() {
  struct sigaction action {};
  action.sa_handler = OnStopSignal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;  // reads and writes in progress go on; the loops poll StopRequested()
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

StopScope::StopScope() { g_scopes.fetch_add(1); }
StopScope::~StopScope() { g_scopes.fetch_sub(1); }

bool StopRequested() { return g_signal.load() != 0; }

int StopExitCode() {
  const int number = g_signal.load();
  return number == 0 ? 0 : 128 + number;
}

}  // namespace nerfar

#include "calib/core/log.h"

#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <mutex>

namespace nerfar {
namespace {
std::atomic<LogLevel> g_level{LogLevel::kNormal};
std::mutex g_stderr_mutex;

void Emit(const std::string& line) {
  std::lock_guard<std::mutex> lock(g_stderr_mutex);
  std::fprintf(stderr, "%s\n", line.c_str());
  std::fflush(stderr);
}
}  // namespace

void SetLogLevel(LogLevel level) { g_level = level; }
LogLevel GetLogLevel() { return g_level; }

void LogInfo(const std::string& message) {
  if (g_level.load() >= LogLevel::kNormal) Emit(message);
}
void LogVerbose(const std::string& message) {
  if (g_level.load() >= LogLevel::kVerbose) Emit(message);
}
void LogWarning(const std::string& message) { Emit("warning: " + message); }

std::string FormatDuration(double seconds) {
  char buffer[64];
  if (seconds < 1.0) {
    std::snprintf(buffer, sizeof buffer, "%.0fms", seconds * 1e3);
  } else if (seconds < 60.0) {
    std::snprintf(buffer, sizeof buffer, "%.1fs", seconds);
  } else {
    const long total = static_cast<long>(seconds + 0.5);
    std::snprintf(buffer, sizeof buffer, "%ldm%02lds", total / 60, total % 60);
  }
  return buffer;
}

Progress::Progress(std::string name, size_t total)
    : name_(std::move(name)),
      total_(total),
      terminal_(::isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()),
      last_print_(start_) {}

Progress::~Progress() {
  if (!finished_) Finish();
}

double Progress::ElapsedSeconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::Update(size_t done, const std::string& status) {
  done_ = done;
  status_ = status;
  const auto now = std::chrono::steady_clock::now();
  const double since_print = std::chrono::duration<double>(now - last_print_).count();
  // A terminal redraws often; a log file gets a line every 5 s at most.
  if (since_print < (terminal_ ? 0.1 : 5.0)) return;
  last_print_ = now;
  Print(false);
}

void Progress::Finish(const std::string& status) {
  if (finished_) return;
  finished_ = true;
  if (total_) done_ = total_;
  if (!status.empty()) status_ = status;
  Print(true);
}

void Progress::Print(bool final_line) {
  if (GetLogLevel() == LogLevel::kQuiet) return;
  const double elapsed = ElapsedSeconds();
  std::string line = name_ + ": ";
  char buffer[160];
  if (total_ > 0) {
    const double fraction = static_cast<double>(done_) / static_cast<double>(total_);
    if (terminal_) {
      const int width = 24, filled = static_cast<int>(fraction * width + 0.5);
      line += "[" + std::string(filled, '#') + std::string(width - filled, '.') + "] ";
    }
    std::snprintf(buffer, sizeof buffer, "%3.0f%% (%zu/%zu)", fraction * 100.0, done_, total_);
    line += buffer;
    if (final_line) {
      line += ", took " + FormatDuration(elapsed);
    } else if (done_ > 0) {
      line += ", ETA " + FormatDuration(elapsed * (1.0 - fraction) / fraction);
    }
  } else {
    line += std::to_string(done_) + ", " + FormatDuration(elapsed);
  }
  if (!status_.empty()) line += ", " + status_;
  std::lock_guard<std::mutex> lock(g_stderr_mutex);
  if (terminal_) {
    std::fprintf(stderr, "\r\033[K%s%s", line.c_str(), final_line ? "\n" : "");
  } else {
    std::fprintf(stderr, "%s\n", line.c_str());
  }
  std::fflush(stderr);
}

}  // namespace nerfar

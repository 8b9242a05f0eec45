// Log lines on stderr with a level set once by --quiet / --verbose, and a
// progress reporter for long jobs: a bar with ETA on a terminal, plain
// "name: 40% (12/30), ETA 1m05s" lines every few seconds otherwise.
#pragma once

#include <chrono>
#include <string>

namespace nerfar {

enum class LogLevel { kQuiet = 0, kNormal = 1, kVerbose = 2 };

void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();

void LogInfo(const std::string& message);     // normal and verbose
void LogVerbose(const std::string& message);  // verbose only
void LogWarning(const std::string& message);  // always, prefixed "warning: "

// "1m05s", "12.3s", "850ms".
std::string FormatDuration(double seconds);

class Progress {
 public:
  // total may be 0 when unknown (no percentage or ETA then).
  Progress(std::string name, size_t total);
  ~Progress();
  // Sets the number of finished items; `status` is a short suffix ("loss 0.012").
  void Update(size_t done, const std::string& status = "");
  void Finish(const std::string& status = "");
  double ElapsedSeconds() const;

 private:
  void Print(bool final_line);

  std::string name_;
  size_t total_;
  size_t done_ = 0;
  std::string status_;
  bool terminal_;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_print_;
};

}  // namespace nerfar

#include "app/video.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "calib/core/atomic_file.h"

namespace nerfar {

namespace {

std::vector<std::string> Mp4Arguments(const std::string& frame_pattern, double fps, const std::string& output) {
  std::ostringstream rate;
  rate << fps;
  return {"ffmpeg",      "-hide_banner", "-loglevel", "error",    "-y",      "-framerate", rate.str(),   "-i",
          frame_pattern, "-c:v",         "libx264",   "-pix_fmt", "yuv420p", "-movflags",  "+faststart", output};
}

// Runs argv (no shell: paths need no quoting); its exit status, −1 when it could not start.
int RunProgram(const std::vector<std::string>& arguments) {
  std::vector<char*> argv;
  for (const std::string& a : arguments) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid < 0) return -1;
  if (pid == 0) {
    execvp(argv[0], argv.data());
    _exit(127);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) < 0) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

std::optional<std::string> FindOnPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::istringstream folders(path != nullptr ? path : "");
  for (std::string folder; std::getline(folders, folder, ':');) {
    const std::filesystem::path candidate = std::filesystem::path(folder.empty() ? "." : folder) / name;
    if (access(candidate.c_str(), X_OK) == 0) return candidate.string();
  }
  return std::nullopt;
}

std::string Mp4Command(const std::string& frame_pattern, double fps, const std::string& output) {
  std::string line;
  for (const std::string& a : Mp4Arguments(frame_pattern, fps, output))
    line += (line.empty() ? "" : " ") + (a.find_first_of(" '\"$") == std::string::npos ? a : "'" + a + "'");
  return line;
}

void EncodeMp4(const std::string& frame_pattern, double fps, const std::string& output) {
  if (!FindOnPath("ffmpeg"))
    throw std::runtime_error(output + ": ffmpeg not found on PATH (install it: apt-get install ffmpeg); the frames " +
                             "are kept, encode them with: " + Mp4Command(frame_pattern, fps, output));
  AtomicFile file(output);  // the temporary keeps the .mp4 extension, which picks ffmpeg's muxer
  const int status = RunProgram(Mp4Arguments(frame_pattern, fps, file.temp_path()));
  if (status != 0)
    throw std::runtime_error(output + ": ffmpeg failed (exit status " + std::to_string(status) +
                             "); the frames are kept, the command was: " + Mp4Command(frame_pattern, fps, output));
  file.Commit();
}

}  // namespace nerfar

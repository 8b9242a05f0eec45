// Videos of rendered frames through Debian's ffmpeg program: H.264 in an
// MP4 (yuv420p, which browsers and phones play; OpenCV's VideoWriter, which
// `live` streams to, writes MPEG-4 Part 2 instead).
#pragma once

#include <optional>
#include <string>

namespace nerfar {

// The executable `name` on PATH, if any.
std::optional<std::string> FindOnPath(const std::string& name);

// The command that turns PNG frames named like `frame_pattern` (printf style,
// "DIR/frame_%04d.png") into `output` at `fps`, for the user to run by hand.
std::string Mp4Command(const std::string& frame_pattern, double fps, const std::string& output);

// Encodes the frames into `output` (written to a temporary file, then
// renamed). std::runtime_error naming the command when ffmpeg is not on
// PATH or fails.
void EncodeMp4(const std::string& frame_pattern, double fps, const std::string& output);

}  // namespace nerfar

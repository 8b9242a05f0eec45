// nerfar cameras: what is attached (V4L2 devices with formats and controls,
// libcamera cameras), and plainly when nothing is.
#include <cstdio>

#include "app/cli.h"
#include "app/commands.h"
#include "tracking/frame_sources.h"

namespace nerfar {

int RunCameras(const CommandArgs& args) {
  ArgParser parser("cameras", "List the cameras attached (V4L2 and libcamera) with their formats and controls.");
  if (!parser.Parse(args)) return 0;
  std::vector<CameraInfo> cameras = ListV4l2Cameras();
  std::string note;
  for (CameraInfo& c : ListLibcameraCameras(note)) cameras.push_back(std::move(c));
  for (const CameraInfo& c : cameras) {
    std::printf("%s  %s  %s\n", c.source.c_str(), c.name.c_str(), c.bus.c_str());
    if (!c.error.empty()) std::printf("  error: %s\n", c.error.c_str());
    for (const CameraFormat& f : c.formats) {
      std::printf("  %s %s\n", f.fourcc.c_str(), f.description.c_str());
      for (const std::string& s : f.sizes) std::printf("    %s\n", s.c_str());
    }
    for (const std::string& control : c.controls) std::printf("  control %s\n", control.c_str());
  }
  if (cameras.empty()) {
    std::printf("no camera attached (no V4L2 capture device in /dev; libcamera: %s).\n",
                note.empty() ? "none" : note.c_str());
    std::printf("Commands that take --source still work on files: images:DIR, video:FILE, or synthetic.\n");
  }
  return 0;
}

}  // namespace nerfar

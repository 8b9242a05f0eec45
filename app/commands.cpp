#include "app/commands.h"

namespace nerfar {

const std::vector<Command>& AllCommands() {
  // In pipeline order; `nerfar help` prints them as listed.
  static const std::vector<Command> commands = {
      {"help", "list the commands, or show one command's help", RunHelp},
      {"version", "print the version and the libraries it was built with", RunVersion},
      {"board", "a tag board to print: vector PDF at exact scale, PNGs and its board.json (the first step)", RunBoard},
      {"calibrate", "camera intrinsics and distortion from AprilTag board views (camera.json)", RunCalibrate},
      {"cameras", "list the cameras attached (V4L2, libcamera) with formats and controls", RunCameras},
      {"track", "camera pose per frame from the board's AprilTags; poses.json in the transforms.json convention",
       RunTrack},
      {"capture", "an HDR capture session: tracked, sharp, spread-out views written as a dataset", RunCapture},
      {"synth", "render a procedural tabletop scene with exact ground truth (dataset layout)", RunSynth},
      {"import", "bring a capture made with other tools (transforms.json) into nerfar's frame: metres, z up, a box",
       RunImport},
      {"train", "train the HDR NeRF of a dataset (checkpoints, resumes, presets)", RunTrain},
      {"env", "estimate the distant environment light (32 SGs, env.json) that the NeRF does not hold", RunEnv},
      {"render", "render a NeRF at a dataset's cameras: colour, depth, opacity EXR and psnr_tm report", RunRender},
      {"bake", "bake the SSDF visibility field of a virtual object (shadows, self-shadows)", RunBake},
      {"insert", "insert virtual objects into a scene's views: light, shade, occlude, shadow, composite", RunInsert},
      {"live", "the live AR view: tracked frames with the object placed, lit and shadowed (window or files)", RunLive},
      {"report", "the report of a live session: calibration, tracking, light, environment, SSDF, timings", RunReport},
      {"demo", "from nothing to a running AR sequence on the built-in synthetic scene (resumable)", RunDemo},
      {"bench", "measure each stage's speed and accuracy; print a table and write JSON", RunBench},
  };
  return commands;
}

}  // namespace nerfar

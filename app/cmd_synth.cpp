// nerfar synth --scene NAME -o DIR [--res WxH --views N --test-views M --spp S --seed K --bounce]
// Renders a procedural tabletop scene with exact ground truth into the layout
// of ../shared/scenes/README.md (see render/synth/writer.h).
#include <cstdio>
#include <string>

#include "app/cli.h"
#include "app/commands.h"
#include "calib/core/error.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "render/synth/writer.h"

namespace nerfar {

namespace {

void ParseResolution(const std::string& text, int& width, int& height) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
    throw InputError("nerfar synth: --res '" + text + "' (expected WIDTHxHEIGHT, e.g. 400x300)");
  width = w;
  height = h;
}

}  // namespace

int RunSynth(const CommandArgs& args) {
  synth::SynthOptions options;
  std::string res, preset, names;
  for (const std::string& n : synth::SynthSceneNames()) names += (names.empty() ? "" : " | ") + n;
  int seed = static_cast<int>(options.seed);
  bool no_insert = false;
  ArgParser parser("synth", "Render a procedural tabletop scene with exact ground truth (HDR dataset layout).");
  parser.Option("--scene", &options.scene, "NAME", names + " (default lamps)");
  parser.Option("-o", &options.output_dir, "DIR", "output folder (created; files in it are replaced)");
  parser.Required("-o");
  parser.Option("--res", &res, "WxH", "image size (default 400x300; 60 deg horizontal field of view)");
  parser.Option("--views", &options.views, "N", "training views (default 100)");
  parser.Option("--test-views", &options.test_views, "M", "test views, also the insert/ views (default 8)");
  parser.Option("--preset", &preset, "P", "fast | balanced (default) | accurate: the sample counts below");
  parser.Option("--spp", &options.spp, "S", "samples per pixel of train/test views (balanced: 16)");
  parser.Option("--insert-spp", &options.insert_spp, "S", "samples per pixel of insert/ renders (balanced: 64)");
  parser.Option("--probe-spp", &options.probe_spp, "S", "samples per probe pixel (balanced: 16)");
  parser.Option("--seed", &seed, "K", "fixes the scene, cameras and noise (default 1)");
  parser.Flag("--bounce", &options.bounce, "add one bounce of indirect light (about 2x the time)");
  parser.Flag("--no-insert", &no_insert, "skip insert/ and objects/ (ground truth for insertion)");
  parser.Option("--contact-sheet", &options.contact_sheet_views, "N",
                "views tiled into DIR/contact_sheet.png (default 12)");
  parser.Epilog(
      "Writes transforms.json (= transforms_train.json), transforms_test.json, train/ and test/ r_XXX.exr, "
      "board.json,\n"
      "lights.json, env.exr, objects/, insert/ (bg, rgb, mask, depth, probe, pose per object) and contact_sheet.png.\n"
      "Example: nerfar synth --scene window -o /tmp/window --res 64x48 --views 24 --spp 4");
  // Presets set the sample counts; explicit flags given after win, so parse twice.
  if (!parser.Parse(args)) return 0;
  if (!preset.empty()) {
    synth::SynthOptions preset_options = options;
    if (!preset_options.ApplyPreset(preset))
      throw InputError("nerfar synth: --preset '" + preset + "' (expected fast, balanced or accurate)");
    options = preset_options;
    parser.Parse(args);  // explicit sample counts override the preset
  }
  if (!res.empty()) ParseResolution(res, options.width, options.height);
  if (seed < 0) throw InputError("nerfar synth: --seed " + std::to_string(seed) + " (expected >= 0)");
  options.seed = static_cast<uint64_t>(seed);
  options.insert = !no_insert;
  {
    Problems problems("nerfar synth");
    for (const std::string& p : options.Validate()) problems.Add("", p);
    problems.ThrowIfAny();
  }
  LogInfo("synth: scene " + options.scene + ", " + std::to_string(options.width) + "x" +
          std::to_string(options.height) + ", " + std::to_string(options.views) + "+" +
          std::to_string(options.test_views) + " views, spp " + std::to_string(options.spp) + "/" +
          std::to_string(options.insert_spp) + "/" + std::to_string(options.probe_spp) + ", seed " +
          std::to_string(options.seed) + (options.bounce ? ", one bounce" : "") + ", " + std::to_string(ThreadCount()) +
          " threads -> " + options.output_dir);
  const synth::SynthReport report = synth::WriteSynthDataset(options);
  LogInfo("synth: " + std::to_string(report.images) + " images in " + FormatDuration(report.seconds_total) +
          " (train+test " + FormatDuration(report.seconds_train_test) + ", insert " +
          FormatDuration(report.seconds_insert) + ")");
  return 0;
}

}  // namespace nerfar

// nerfar train DATASET -o scene.nerf [--preset P] [--minutes M] [--set key=value]...
// Trains the HDR NeRF; checkpoints beside the output (OUTPUT.ckpt) every few
// seconds and on SIGINT (Ctrl-C) or SIGTERM; running the same command again
// resumes from it.
// --stop-at-step N writes the model of step N and keeps the checkpoint, so the
// coarse levels of a long schedule can be looked at before it is resumed.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "app/cli.h"
#include "app/command_files.h"
#include "app/commands.h"
#include "app/stop_signal.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/log.h"
#include "render/nerf/nerf_file.h"
#include "render/nerf/nerf_train.h"

namespace nerfar {
namespace {

std::string Fixed(double v, int digits) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", digits, v);
  return buffer;
}

}  // namespace

int RunTrain(const CommandArgs& args) {
  std::string dataset, output, preset = "balanced";
  double minutes = 0, checkpoint_seconds = 60;
  int stop_at_step = 0;
  std::vector<std::string> sets;
  bool restart = false;
  ArgParser parser("train", "Train the HDR NeRF of a dataset (transforms.json + linear EXR images).");
  parser.Positional("DATASET", &dataset, "dataset folder (transforms_train.json or transforms.json, images)");
  parser.Option("-o", &output, "FILE", "output model (.nerf); its checkpoint is FILE.ckpt");
  parser.Required("-o");
  parser.Option("--preset", &preset, "P", "fast | balanced (default) | accurate");
  parser.Option("--minutes", &minutes, "M", "wall-clock budget: the schedule is compressed to end in M minutes");
  parser.Option("--set", &sets, "KEY=VALUE", "override one training option (repeatable; see below)");
  parser.Option(
      "--checkpoint-seconds", &checkpoint_seconds, "S",
      "seconds at least between checkpoints (default 60; longer where writing one would take over ~5 % of the time)");
  parser.Option("--stop-at-step", &stop_at_step, "N",
                "stop after step N: write the model of that step and keep the checkpoint (the command without "
                "this option resumes)");
  parser.Flag("--restart", &restart, "ignore an existing checkpoint and start over");
  parser.Epilog("Options (--set): " + NerfTrainOptions::Preset("balanced").ToJson() +
                "\nCtrl-C or SIGTERM stops after the current step and keeps a checkpoint; the same command resumes.\n"
                "Example: nerfar train ../shared/scenes/lamps -o lamps.nerf --preset fast");
  if (!parser.Parse(args)) return 0;
  if (minutes < 0) throw InputError("nerfar train: --minutes must be >= 0");
  if (checkpoint_seconds <= 0) throw InputError("nerfar train: --checkpoint-seconds must be > 0");
  if (stop_at_step < 0) throw InputError("nerfar train: --stop-at-step must be >= 0 (0: none)");

  NerfTrainOptions options = NerfTrainOptions::Preset(preset);
  for (const std::string& s : sets) options.Set(s);
  if (minutes > 0) options.max_seconds = minutes * 60.0;
  {
    const std::vector<std::string> problems = options.Validate();
    if (!problems.empty()) {
      Problems list("nerfar train");
      for (const std::string& p : problems) list.Add("options", p);
      list.ThrowIfAny();
    }
  }
  const std::string checkpoint = output + ".ckpt";
  CheckOutputsSpareInputs({output, checkpoint}, DatasetFolderInputs(dataset));
  const NerfTrainData data = ReadNerfTrainData(dataset);
  LogInfo("train: " + std::to_string(data.train.size()) + " training views, " + std::to_string(data.held_out.size()) +
          " held-out; preset " + preset + "; options " + options.ToJson());

  NerfTrainer trainer(data, options);
  std::error_code error;
  if (!restart && std::filesystem::is_regular_file(checkpoint, error)) {
    trainer.LoadCheckpoint(checkpoint);
    LogInfo("train: resumed from " + checkpoint + " at step " + std::to_string(trainer.step()) + " (" +
            FormatDuration(trainer.elapsed_seconds()) + " trained)");
  }

  const StopScope stop_scope;  // a signal ends the current step, then the checkpoint is written
  // Progress counts schedule per-mille so the ETA is right under a time budget too.
  Progress progress("train", 1000);
  double last_checkpoint = trainer.elapsed_seconds(), last_eval = -1e9, eval_gap = 20.0;
  double checkpoint_gap = checkpoint_seconds;
  double loss = 0, psnr = std::nan("");
  const auto stop_here = [&] { return stop_at_step > 0 && trainer.step() >= stop_at_step; };
  while (!trainer.Done() && !StopRequested() && !stop_here()) {
    loss = trainer.Step();
    const double now = trainer.elapsed_seconds();
    // Held-out PSNR every 30 s, but never more than ~5 % of the time (a
    // foggy early field on a loaded machine renders slowly); eval_views 0: none.
    if (options.eval_views > 0 && now - last_eval > eval_gap) {
      psnr = trainer.HeldOutPsnr(options.eval_views);
      last_eval = trainer.elapsed_seconds();
      LogVerbose("train: held-out psnr_tm " + Fixed(psnr, 2) + " dB at step " + std::to_string(trainer.step()) +
                 " took " + FormatDuration(last_eval - now));
      eval_gap = std::max(30.0, 19.0 * (last_eval - now));
    }
    progress.Update(size_t(trainer.progress() * 1000), "step " + std::to_string(trainer.step()) + " level " +
                                                           std::to_string(trainer.level()) + " loss " + Fixed(loss, 5) +
                                                           " held-out psnr_tm " + Fixed(psnr, 2));
    if (now - last_checkpoint > checkpoint_gap) {
      trainer.SaveCheckpoint(checkpoint);
      last_checkpoint = trainer.elapsed_seconds();
      // Never more than ~5 % of the time: an accurate model's checkpoint is
      // ~1.2 GB (6 s a write under load: 10 % of the time at 60 s).
      checkpoint_gap = std::max(checkpoint_seconds, 19.0 * (last_checkpoint - now));
    }
  }
  if (StopRequested()) {
    trainer.SaveCheckpoint(checkpoint);
    progress.Finish("interrupted");
    LogInfo("train: stopped at step " + std::to_string(trainer.step()) + "; checkpoint " + checkpoint +
            " (run the same command to resume)");
    return StopExitCode();
  }
  const bool partial = !trainer.Done();  // --stop-at-step: keep the checkpoint to resume
  if (partial) trainer.SaveCheckpoint(checkpoint);
  const NerfField field = trainer.FinalField();
  SaveNerf(output, field);
  // A partial model is scored by 'nerfar render' when wanted; not here.
  const double final_psnr = partial ? std::nan("") : trainer.HeldOutPsnr(0);
  progress.Finish("step " + std::to_string(trainer.step()) + " loss " + Fixed(loss, 5));
  std::error_code size_error;
  const auto bytes = std::filesystem::file_size(output, size_error);
  std::printf("trained %s: %d steps in %s, held-out psnr_tm %.2f dB (%zu views), %.1f MB, %.2f%% cells occupied\n",
              output.c_str(), trainer.step(), FormatDuration(trainer.elapsed_seconds()).c_str(), final_psnr,
              data.held_out.size(), size_error ? 0.0 : double(bytes) / 1e6, 100.0 * field.OccupiedFraction());
  if (partial)
    LogInfo("train: stopped at step " + std::to_string(trainer.step()) + " as asked; checkpoint " + checkpoint +
            " kept (run without --stop-at-step to resume)");
  else
    std::filesystem::remove(checkpoint, error);
  return 0;
}

}  // namespace nerfar

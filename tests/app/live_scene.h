// The scene the live-app tests share: the lamps tag board seen by a nearly
// still synthetic camera, and a plain table (no sphere, no medium, no checker)
// as the NeRF stand-in, so an inserted ball is the only thing that changes.
#pragma once

#include "render/insert/scene_field.h"
#include "render/synth/camera_stream.h"

namespace nerfar {

inline synth::CameraStreamOptions NearlyStillLampsStream() {
  synth::CameraStreamOptions stream;
  stream.scene = "lamps";
  stream.width = 640;  // tracked at this size (small tags need the pixels), composited at half
  stream.height = 480;
  stream.samples_per_pixel = 1;
  stream.speed = 1e-4;  // the camera barely moves: frames a second apart compare pixel for pixel
  return stream;
}

inline AnalyticSceneParams PlainTable() {
  AnalyticSceneParams table;
  table.has_sphere = false;
  table.has_medium = false;
  table.checker_size_m = 0;
  return table;
}

}  // namespace nerfar

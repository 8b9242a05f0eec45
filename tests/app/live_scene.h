// The scene the live-app tests share: the lamps tag board seen by a nearly
// still synthetic camera; the NeRF stand-in is the insertion tests' plain
// table (testing::PlainTable), so an inserted ball is the only thing that changes.
#pragma once

#include "render/lighting/scene_field.h"
#include "render/synth/camera_stream.h"
#include "tests/insert/insert_fixtures.h"

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

}  // namespace nerfar

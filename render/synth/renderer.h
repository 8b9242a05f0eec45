// The synthetic renderer: camera rays with a box filter over each pixel,
// next-event estimation of every light with shadow rays, optional one-bounce
// indirect light. Output is linear HDR RGB in image units; rays that hit
// nothing are black (the environment is never seen directly). Every pixel
// sample has its own random stream derived from (seed, stream, pixel, sample),
// so images depend only on the seed, never on the thread count.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/image.h"
#include "calib/core/math.h"
#include "render/synth/scene.h"

namespace nerfar::synth {

struct RenderOptions {
  int spp = 16;         // samples per pixel (stratified when a square number); noise ~ 1/sqrt(spp)
  bool bounce = false;  // add one bounce of indirect light (about 2x the time)
  uint64_t seed = 1;    // base seed; with `stream` it fixes every random number
  // Every problem with the values ("spp: ..."), empty when valid.
  std::vector<std::string> Validate() const;
};

// Renders one view. T_world_camera uses OpenCV camera axes (x right, y down,
// z forward); the camera has no distortion (it is ignored). `stream` separates
// the random numbers of different views (use the view index).
ImageF RenderView(const Scene& scene, const CameraIntrinsics& camera, const Pose& T_world_camera,
                  const RenderOptions& options, uint64_t stream);

// One ray per pixel centre: depth along the viewing axis (z in the OpenCV
// camera frame, metres; 0 where nothing is hit) and a mask, 255 where the
// first surface belongs to object `object_id` (0 elsewhere).
void RenderFirstHit(const Scene& scene, const CameraIntrinsics& camera, const Pose& T_world_camera, int object_id,
                    ImageF& depth, Image8& mask);

// Equirect panorama (README convention) of the radiance arriving at `point`
// from every direction: emitters, lit surfaces (their outgoing radiance towards
// the point, estimated like a camera ray) and the environment where nothing
// is in the way. `spp` stratified directions per pixel.
ImageF RenderProbe(const Scene& scene, const Vec3& point, int width, int height, const RenderOptions& options);

// The environment alone as an equirect panorama: each pixel is the mean of
// `supersample`^2 directions on a regular grid inside it. Black when absent.
ImageF RenderEnvironment(const Scene& scene, int width, int height, int supersample = 4);

// Irradiance (W/m^2 in image units times pi: E such that a Lambertian surface
// of albedo a has radiance a E / pi) at a surface point with normal `normal`,
// by next-event estimation with `samples` samples per light (and one bounce if
// options.bounce). The point must lie on a surface (shadow rays start just
// above it along the normal).
Vec3f EstimateIrradiance(const Scene& scene, const Vec3f& point, const Vec3f& normal, int samples,
                         const RenderOptions& options, uint64_t stream);
}  // namespace nerfar::synth

// Bench stage "synth": scene construction, one dataset view per scene and
// preset, and a frame of the synthetic camera stream; plus the renderer's
// error against the closed-form SG irradiance (a plane under the "sun" sky).
#include <cmath>
#include <string>

#include "app/bench.h"
#include "render/synth/camera_stream.h"
#include "render/synth/reference.h"
#include "render/synth/renderer.h"
#include "render/synth/scenes.h"
#include "render/synth/writer.h"

namespace nerfar {

std::vector<BenchFigure> BenchSynth(const BenchOptions& options) {
  using namespace synth;
  std::vector<BenchFigure> figures;
  const int width = options.quick ? 100 : 400, height = options.quick ? 75 : 300;
  const std::string size = std::to_string(width) + "x" + std::to_string(height);
  for (const std::string name : {"lamps", "window"}) {
    double build_ms = MedianMilliseconds([&] { MakeSynthScene(name, 1); }, 1, 0.0);
    figures.push_back({"scene_build_" + name + "_ms", build_ms, "ms", "table texture, tags, BVH"});
    const SynthScene scene = MakeSynthScene(name, 1);
    const CameraIntrinsics camera = SynthCamera(width, height);
    const Pose pose = HemisphereCameras(1, 1, 1, scene.aabb)[0];
    for (const std::string preset : {"fast", "balanced"}) {
      SynthOptions o;
      o.ApplyPreset(preset);
      RenderOptions render;
      render.spp = o.spp;
      const double ms = MedianMilliseconds([&] { RenderView(scene.scene, camera, pose, render, 0); }, 1, 0.0);
      figures.push_back({"view_" + name + "_" + preset + "_ms", ms, "ms", size + ", spp " + std::to_string(o.spp)});
    }
  }
  CameraStreamOptions stream;
  stream.width = options.quick ? 320 : 640;
  stream.height = options.quick ? 240 : 480;
  SyntheticCameraSource source(stream);
  double t = 0;
  figures.push_back({"stream_frame_ms", MedianMilliseconds([&] { source.RenderFrame(t += 0.033, 0); }, 5, 0.5), "ms",
                     std::to_string(stream.width) + "x" + std::to_string(stream.height) + ", 4 samples/px"});
  // Accuracy: a white plane under the "sun" SG environment vs the closed form.
  Scene plane;
  SurfaceMaterial white;
  white.albedo = {1, 1, 1};
  plane.rectangles.push_back({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 50.0f, 50.0f, plane.AddMaterial(white), -1});
  plane.environment = MakeSynthScene("sun", 1).scene.environment;
  plane.Build();
  const Vec3 e = SgIrradiance(plane.environment.lobes, {0, 0, 1});
  for (int spp : {4, 16}) {
    RenderOptions render;
    render.spp = spp;
    const ImageF image = RenderView(plane, SynthCamera(64, 48), LookAt({0, 0, 1}, {0, 0, 0}), render, 0);
    double sq = 0;
    for (size_t i = 0; i < image.PixelCount(); ++i) {
      const double rel = image.pixels[i * 3 + 1] / (e.y / kPi) - 1;
      sq += rel * rel;
    }
    figures.push_back({"sg_plane_rms_rel_err_spp" + std::to_string(spp), std::sqrt(sq / image.PixelCount()), "",
                       "per-pixel relative RMS vs closed form, 64x48"});
  }
  return figures;
}

}  // namespace nerfar

#include "app/sources.h"

#include <cstdlib>
#include <mutex>
#include <sstream>

#include "calib/core/error.h"
#include "render/synth/camera_stream.h"
#include "tracking/frame_sources.h"
#include "tracking/simulated_exposure.h"

namespace nerfar {
namespace {

double ParseNumber(const std::string& key, const std::string& value) {
  char* end = nullptr;
  const double number = std::strtod(value.c_str(), &end);
  if (value.empty() || *end != '\0') ThrowInputError("synthetic", key + "=" + value + " is not a number");
  return number;
}

synth::CameraStreamOptions ParseSyntheticOptions(const std::string& argument) {
  synth::CameraStreamOptions options;
  std::stringstream parts(argument);
  std::string part;
  bool first = true;
  while (std::getline(parts, part, ',')) {
    const size_t eq = part.find('=');
    if (first && eq == std::string::npos) {
      if (!part.empty()) options.scene = part;
      first = false;
      continue;
    }
    first = false;
    if (eq == std::string::npos) ThrowInputError("synthetic", "'" + part + "' is not key=value");
    const std::string key = part.substr(0, eq), value = part.substr(eq + 1);
    if (key == "seed") {
      options.seed = static_cast<uint64_t>(ParseNumber(key, value));
    } else if (key == "frames") {
      options.frames = static_cast<int>(ParseNumber(key, value));
    } else if (key == "size") {
      if (std::sscanf(value.c_str(), "%dx%d", &options.width, &options.height) != 2)
        ThrowInputError("synthetic", "size=" + value + " (expected WxH)");
    } else if (key == "fps") {
      options.fps = ParseNumber(key, value);
    } else if (key == "noise") {
      options.noise_sigma = ParseNumber(key, value);
    } else if (key == "blur") {
      options.shutter_s = ParseNumber(key, value);
    } else if (key == "exposure") {
      options.exposure_variation = ParseNumber(key, value);
    } else if (key == "speed") {
      options.speed = ParseNumber(key, value);
    } else if (key == "spp") {
      options.samples_per_pixel = static_cast<int>(ParseNumber(key, value));
    } else {
      ThrowInputError("synthetic", "unknown key '" + key +
                                       "' (expected seed, frames, size, fps, noise, blur, exposure, speed, spp)");
    }
  }
  return options;  // the source validates the values itself
}

void RegisterAppSchemes() {
  static std::once_flag once;
  std::call_once(once, [] {
    RegisterFrameSourceScheme(
        "synthetic",
        [](const std::string& argument, const SourceOptions&) -> std::unique_ptr<FrameSource> {
          // ",exposure-control": brackets through the frames' display response
          // (tracking/simulated_exposure.h), as if taken at 10 ms.
          std::string rest = argument;
          const std::string flag = ",exposure-control";
          const size_t at = rest.find(flag);
          if (at != std::string::npos) rest.erase(at, flag.size());
          auto source = std::make_unique<synth::SyntheticCameraSource>(ParseSyntheticOptions(rest));
          if (at == std::string::npos) return source;
          return SimulateExposureControl(std::move(source), CameraResponse::Display8(3), 10000.0);
        },
        "synthetic[:SCENE][,seed=K,frames=N,size=WxH,fps=F,noise=S,blur=T,exposure=V,speed=X,spp=P,exposure-control]: "
        "a rendered tag scene with known poses (scenes: lamps, window)");
  });
}

}  // namespace

std::unique_ptr<FrameSource> OpenSource(const std::string& source) { return OpenSource(source, SourceOptions{}); }

std::unique_ptr<FrameSource> OpenSource(const std::string& source, const SourceOptions& options) {
  RegisterAppSchemes();
  return OpenFrameSource(source, options);
}

std::string SourceHelp() {
  RegisterAppSchemes();
  std::string help = "sources:\n";
  for (const std::string& line : FrameSourceSchemes()) help += "  " + line + "\n";
  return help;
}

}  // namespace nerfar

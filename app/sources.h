// Frame sources as the app offers them: everything tracking/ opens (cameras,
// videos, image folders) plus the synthetic camera of render/synth under the
// scheme "synthetic[:SCENE][,key=value...]" (keys: seed, frames, size=WxH,
// fps, noise, blur (shutter seconds), exposure (variation), speed, spp), e.g.
// "synthetic:window,frames=300,noise=2". "synthetic" alone is the lamps scene
// at 640x480, endless.
#pragma once

#include <memory>
#include <string>

#include "calib/core/frame_source.h"

namespace nerfar {

struct SourceOptions;

std::unique_ptr<FrameSource> OpenSource(const std::string& source);
std::unique_ptr<FrameSource> OpenSource(const std::string& source, const SourceOptions& options);

// The help text listing every scheme, for --help epilogues.
std::string SourceHelp();

}  // namespace nerfar

// Internal to tracking/: the camera back ends behind OpenFrameSource and the
// listings (each in its own .cpp so its system headers stay there).
#pragma once

#include <memory>
#include <string>

#include "tracking/frame_sources.h"

namespace nerfar::detail {

std::unique_ptr<FrameSource> OpenV4l2Source(const std::string& device, const CameraControls& controls);
std::unique_ptr<FrameSource> OpenLibcameraSource(const std::string& camera, const CameraControls& controls);
std::unique_ptr<FrameSource> OpenVideoSource(const std::string& path_or_url, const SourceOptions& options);
std::unique_ptr<FrameSource> OpenImageFolderSource(const std::string& dir, const SourceOptions& options);

}  // namespace nerfar::detail

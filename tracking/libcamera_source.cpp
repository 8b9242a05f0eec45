// libcamera cameras (built when libcamera-dev is present; otherwise the
// source reports that it is not built in). One camera manager per process;
// frames in RGB888 (or the closest the pipeline offers: BGR888, XRGB8888),
// mapped from the dmabuf planes. Controls: exposure time, analogue gain,
// white balance temperature and frame duration where the camera has them.
#include "calib/core/error.h"
#include "tracking/camera_backends.h"

#ifdef NERFAR_HAVE_LIBCAMERA
#include <libcamera/libcamera.h>
#include <sys/mman.h>

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <mutex>

#include "calib/core/log.h"

namespace nerfar {
namespace {
namespace lc = libcamera;

// The process-wide manager (libcamera allows one).
lc::CameraManager& Manager(std::string& error) {
  static std::unique_ptr<lc::CameraManager> manager;
  static int status = 1;
  static std::once_flag once;
  std::call_once(once, [] {
    manager = std::make_unique<lc::CameraManager>();
    status = manager->start();
  });
  if (status != 0) error = "libcamera could not start (" + std::string(std::strerror(-status)) + ")";
  return *manager;
}

class LibcameraSource : public FrameSource {
 public:
  LibcameraSource(std::shared_ptr<lc::Camera> camera, const CameraControls& controls)
      : camera_(std::move(camera)), controls_(controls) {}

  ~LibcameraSource() override {
    if (started_) camera_->stop();
    camera_->requestCompleted.disconnect(this);
    camera_->disconnected.disconnect(this);
    requests_.clear();
    for (auto& [ptr, length] : maps_) ::munmap(ptr, length);
    allocator_.reset();
    if (acquired_) camera_->release();
  }

  void Start() {
    if (camera_->acquire() != 0) ThrowInputError(camera_->id(), "camera is busy (another program holds it)");
    acquired_ = true;
    config_ = camera_->generateConfiguration({lc::StreamRole::VideoRecording});
    if (!config_ || config_->empty()) ThrowInputError(camera_->id(), "offers no video configuration");
    lc::StreamConfiguration& sc = config_->at(0);
    sc.pixelFormat = lc::formats::RGB888;
    if (controls_.width > 0)
      sc.size = {static_cast<unsigned>(controls_.width), static_cast<unsigned>(controls_.height)};
    sc.bufferCount = static_cast<unsigned>(controls_.buffers);
    if (config_->validate() == lc::CameraConfiguration::Invalid)
      ThrowInputError(camera_->id(), "rejects every configuration we ask for");
    format_ = sc.pixelFormat;
    if (format_ != lc::formats::RGB888 && format_ != lc::formats::BGR888 && format_ != lc::formats::XRGB8888)
      ThrowInputError(camera_->id(), "streams " + format_.toString() + " only (expected an RGB format)");
    if (camera_->configure(config_.get()) != 0) ThrowInputError(camera_->id(), "cannot be configured");
    stream_ = sc.stream();
    width_ = static_cast<int>(sc.size.width);
    height_ = static_cast<int>(sc.size.height);
    stride_ = sc.stride;
    allocator_ = std::make_unique<lc::FrameBufferAllocator>(camera_);
    if (allocator_->allocate(stream_) < 0) ThrowInputError(camera_->id(), "cannot allocate frame buffers");
    for (const std::unique_ptr<lc::FrameBuffer>& buffer : allocator_->buffers(stream_)) {
      std::unique_ptr<lc::Request> request = camera_->createRequest();
      if (!request || request->addBuffer(stream_, buffer.get()) != 0)
        ThrowInputError(camera_->id(), "cannot create capture requests");
      const lc::FrameBuffer::Plane& plane = buffer->planes()[0];
      void* ptr = ::mmap(nullptr, plane.offset + plane.length, PROT_READ, MAP_SHARED, plane.fd.get(), 0);
      if (ptr == MAP_FAILED) ThrowInputError(camera_->id(), "cannot map frame buffers");
      maps_.push_back({ptr, plane.offset + plane.length});
      mapped_[buffer.get()] = static_cast<const std::uint8_t*>(ptr) + plane.offset;
      requests_.push_back(std::move(request));
    }
    camera_->requestCompleted.connect(this, &LibcameraSource::OnComplete);
    camera_->disconnected.connect(this, &LibcameraSource::OnDisconnected);

    lc::ControlList start_controls(camera_->controls());
    const lc::ControlInfoMap& info = camera_->controls();
    auto has = [&](const lc::ControlId& id) { return info.find(&id) != info.end(); };
    std::vector<std::string> missing;
    if (controls_.exposure_us > 0) {
      if (has(lc::controls::ExposureTime)) {
        start_controls.set(lc::controls::AeEnable, false);
        start_controls.set(lc::controls::ExposureTime, static_cast<int32_t>(controls_.exposure_us));
      } else {
        missing.push_back("exposure");
      }
    }
    if (controls_.gain >= 0) {
      if (has(lc::controls::AnalogueGain)) {
        start_controls.set(lc::controls::AeEnable, false);
        start_controls.set(lc::controls::AnalogueGain, static_cast<float>(controls_.gain));
      } else {
        missing.push_back("gain");
      }
    }
    if (controls_.white_balance_k > 0) {
      if (has(lc::controls::ColourTemperature)) {
        start_controls.set(lc::controls::AwbEnable, false);
        start_controls.set(lc::controls::ColourTemperature, static_cast<int32_t>(controls_.white_balance_k));
      } else {
        missing.push_back("white balance");
      }
    }
    if (controls_.fps > 0) {
      if (has(lc::controls::FrameDurationLimits)) {
        const int64_t us = static_cast<int64_t>(1e6 / controls_.fps);
        start_controls.set(lc::controls::FrameDurationLimits, lc::Span<const int64_t, 2>({us, us}));
      } else {
        missing.push_back("frame rate");
      }
    }
    for (const std::string& m : missing) LogWarning(camera_->id() + ": the camera has no " + m + " control");
    if (camera_->start(&start_controls) != 0) ThrowInputError(camera_->id(), "cannot start streaming");
    started_ = true;
    for (std::unique_ptr<lc::Request>& request : requests_) camera_->queueRequest(request.get());
  }

  std::string Describe() const override {
    return "libcamera:" + camera_->id() + " " + std::to_string(width_) + "x" + std::to_string(height_) + " " +
           format_.toString();
  }

  // Exposure brackets: AE and AWB are switched off (held) for the rest of
  // the session, the time goes into the next queued requests, and Next()
  // drops frames until one reports the new exposure in its metadata.
  bool SetExposure(double exposure_us) override {
    const lc::ControlInfoMap& info = camera_->controls();
    if (info.find(&lc::controls::ExposureTime) == info.end()) return false;
    std::lock_guard<std::mutex> lock(mutex_);
    if (!locked_) {
      LogInfo(camera_->id() + ": auto exposure and auto white balance locked for the session");
      locked_ = true;
    }
    pending_exposure_us_ = static_cast<int32_t>(std::lround(exposure_us));
    awaiting_exposure_ = true;
    return true;
  }

  FrameStatus Next(Frame& frame, int timeout_ms) override {
    // Frames exposed before an exposure change are dropped (a bounded number:
    // a camera that ignores the control still delivers).
    for (int dropped = 0;; ++dropped) {
      const FrameStatus status = NextAny(frame, timeout_ms);
      if (status != FrameStatus::kOk || !awaiting_exposure_) return status;
      if (std::abs(last_exposure_us_ - pending_exposure_us_) <= 0.05 * pending_exposure_us_ + 1 ||
          dropped >= static_cast<int>(requests_.size()) + 4) {
        if (dropped >= static_cast<int>(requests_.size()) + 4)
          LogWarning(camera_->id() + ": frames do not report the exposure asked for; using the next one");
        awaiting_exposure_ = false;
        return status;
      }
    }
  }

 private:
  FrameStatus NextAny(Frame& frame, int timeout_ms) {
    lc::Request* request = nullptr;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      if (lost_) {
        error_ = camera_->id() + ": camera disconnected";
        return FrameStatus::kLost;
      }
      if (!ready_.wait_for(lock, std::chrono::milliseconds(std::max(0, timeout_ms)),
                           [&] { return !completed_.empty() || lost_; }))
        return FrameStatus::kTimeout;
      if (lost_) return FrameStatus::kLost;
      request = completed_.front();
      completed_.pop_front();
    }
    FrameStatus status = FrameStatus::kOk;
    if (request->status() != lc::Request::RequestComplete) {
      status = FrameStatus::kCorrupt;
      error_ = camera_->id() + ": request cancelled";
    } else {
      lc::FrameBuffer* buffer = request->buffers().begin()->second;
      const std::uint8_t* src = mapped_[buffer];
      const int bpp = format_ == lc::formats::XRGB8888 ? 4 : 3;
      frame.image = Image8(width_, height_, 3);
      for (int y = 0; y < height_; ++y) {
        const std::uint8_t* row = src + static_cast<size_t>(y) * stride_;
        std::uint8_t* dst = frame.image.Pixel(0, y);
        for (int x = 0; x < width_; ++x) {
          // libcamera's RGB888 is stored B,G,R in memory; BGR888 as R,G,B; XRGB8888 as B,G,R,X.
          const std::uint8_t* p = row + x * bpp;
          const bool rgb_in_memory = format_ == lc::formats::BGR888;
          dst[3 * x + 0] = rgb_in_memory ? p[0] : p[2];
          dst[3 * x + 1] = p[1];
          dst[3 * x + 2] = rgb_in_memory ? p[2] : p[0];
        }
      }
      frame.t_ns = static_cast<std::int64_t>(buffer->metadata().timestamp);
      frame.index = index_++;
      frame.name.clear();
      frame.T_world_camera_true.reset();
    }
    const auto exposure = request->metadata().get(lc::controls::ExposureTime);
    last_exposure_us_ = exposure ? *exposure : -1;
    request->reuse(lc::Request::ReuseBuffers);
    if (locked_) {
      request->controls().set(lc::controls::AeEnable, false);
      request->controls().set(lc::controls::AwbEnable, false);
      request->controls().set(lc::controls::ExposureTime, pending_exposure_us_);
    }
    camera_->queueRequest(request);
    return status;
  }

 public:
  std::string LastError() const override { return error_; }

 private:
  void OnComplete(lc::Request* request) {
    if (request->status() == lc::Request::RequestCancelled) return;
    std::lock_guard<std::mutex> lock(mutex_);
    completed_.push_back(request);
    ready_.notify_one();
  }
  void OnDisconnected() {
    std::lock_guard<std::mutex> lock(mutex_);
    lost_ = true;
    ready_.notify_one();
  }

  std::shared_ptr<lc::Camera> camera_;
  CameraControls controls_;
  std::unique_ptr<lc::CameraConfiguration> config_;
  std::unique_ptr<lc::FrameBufferAllocator> allocator_;
  lc::Stream* stream_ = nullptr;
  lc::PixelFormat format_;
  std::vector<std::unique_ptr<lc::Request>> requests_;
  std::vector<std::pair<void*, size_t>> maps_;
  std::map<const lc::FrameBuffer*, const std::uint8_t*> mapped_;
  int width_ = 0, height_ = 0;
  unsigned stride_ = 0;
  bool acquired_ = false, started_ = false;
  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<lc::Request*> completed_;
  bool lost_ = false;
  bool locked_ = false;             // AE/AWB held since the first SetExposure
  bool awaiting_exposure_ = false;  // drop frames until one has pending_exposure_us_
  int32_t pending_exposure_us_ = 0;
  int32_t last_exposure_us_ = -1;  // from the last frame's metadata
  std::int64_t index_ = 0;
  std::string error_;
};

}  // namespace

namespace detail {
std::unique_ptr<FrameSource> OpenLibcameraSource(const std::string& which, const CameraControls& controls) {
  std::string error;
  lc::CameraManager& manager = Manager(error);
  if (!error.empty()) ThrowInputError("libcamera:" + which, error);
  const std::vector<std::shared_ptr<lc::Camera>> cameras = manager.cameras();
  std::shared_ptr<lc::Camera> camera;
  if (!which.empty() && which.find_first_not_of("0123456789") == std::string::npos && which.size() < 4) {
    const size_t index = std::stoul(which);
    if (index < cameras.size()) camera = cameras[index];
  } else {
    camera = manager.get(which.empty() ? (cameras.empty() ? "" : cameras[0]->id()) : which);
  }
  if (!camera)
    ThrowInputError("libcamera:" + which,
                    "no such camera (" + std::to_string(cameras.size()) + " attached; run 'nerfar cameras')");
  auto source = std::make_unique<LibcameraSource>(camera, controls);
  source->Start();
  return source;
}
}  // namespace detail

std::vector<CameraInfo> ListLibcameraCameras(std::string& note) {
  std::vector<CameraInfo> list;
  std::string error;
  lc::CameraManager& manager = Manager(error);
  if (!error.empty()) {
    note = error;
    return list;
  }
  const auto cameras = manager.cameras();
  for (size_t i = 0; i < cameras.size(); ++i) {
    CameraInfo info;
    info.backend = "libcamera";
    info.source = "libcamera:" + std::to_string(i);
    info.bus = cameras[i]->id();
    const lc::ControlList& props = cameras[i]->properties();
    if (auto model = props.get(lc::properties::Model)) info.name = *model;
    for (const auto& [id, range] : cameras[i]->controls())
      if (id == &lc::controls::ExposureTime || id == &lc::controls::AnalogueGain ||
          id == &lc::controls::ColourTemperature || id == &lc::controls::FrameDurationLimits)
        info.controls.push_back(id->name() + " " + range.toString());
    std::unique_ptr<lc::CameraConfiguration> config =
        cameras[i]->generateConfiguration({lc::StreamRole::VideoRecording});
    if (config && !config->empty()) {
      const lc::StreamFormats& formats = config->at(0).formats();
      for (const lc::PixelFormat& pf : formats.pixelformats()) {
        CameraFormat f;
        f.fourcc = pf.toString();
        for (const lc::Size& s : formats.sizes(pf)) f.sizes.push_back(s.toString());
        info.formats.push_back(f);
      }
    }
    list.push_back(info);
  }
  if (list.empty()) note = "libcamera sees no camera";
  return list;
}

}  // namespace nerfar

#else  // no libcamera

namespace nerfar {
namespace detail {
std::unique_ptr<FrameSource> OpenLibcameraSource(const std::string& which, const CameraControls&) {
  ThrowInputError("libcamera:" + which, "this build has no libcamera support (install libcamera-dev and rebuild)");
}
}  // namespace detail
std::vector<CameraInfo> ListLibcameraCameras(std::string& note) {
  note = "this build has no libcamera support";
  return {};
}
}  // namespace nerfar
#endif

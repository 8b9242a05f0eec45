// V4L2 cameras through libv4l2: the library converts whatever the device
// streams (YUYV, MJPG, Bayer...) to RGB24, so we ask for RGB24 only. mmap
// streaming; frames time-stamped by the driver on the monotonic clock. A
// device that disappears (unplugged) makes Next() return kLost; the source
// then tries to reopen it at most twice a second and streams again.
#include <fcntl.h>
#include <libv4l2.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>

#include "calib/core/error.h"
#include "calib/core/log.h"
#include "tracking/camera_backends.h"

namespace nerfar {
namespace {

// ioctl through libv4l2, retried on EINTR.
int Xioctl(int fd, unsigned long request, void* arg) {
  int r;
  do {
    r = v4l2_ioctl(fd, request, arg);
  } while (r == -1 && errno == EINTR);
  return r;
}

std::string FourCc(uint32_t code) {
  std::string s;
  for (int i = 0; i < 4; ++i) s += static_cast<char>((code >> (8 * i)) & 0xff);
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

std::int64_t MonotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

bool DeviceGone(int error) { return error == ENODEV || error == EIO || error == ENXIO || error == EBADF; }

// Sets one control; returns an empty string or why it failed.
std::string SetControl(int fd, uint32_t id, int value, const char* name) {
  v4l2_control control{};
  control.id = id;
  control.value = value;
  if (Xioctl(fd, VIDIOC_S_CTRL, &control) == 0) return {};
  return std::string(name) + " (" + std::strerror(errno) + ")";
}

class V4l2Source : public FrameSource {
 public:
  V4l2Source(std::string device, const CameraControls& controls) : device_(std::move(device)), controls_(controls) {}
  ~V4l2Source() override { Close(); }

  // Throws InputError naming the device on failure.
  void Open() {
    std::string why;
    if (!TryOpen(why)) ThrowInputError(device_, why);
  }

  std::string Describe() const override {
    return "v4l2:" + device_ + " " + card_ + " " + std::to_string(width_) + "x" + std::to_string(height_) + " " +
           native_fourcc_ + (fps_ > 0 ? " @" + std::to_string(static_cast<int>(std::lround(fps_))) : "");
  }

  FrameStatus Next(Frame& frame, int timeout_ms) override {
    while (drain_ > 0) {
      --drain_;
      const FrameStatus status = NextAny(frame, timeout_ms);
      if (status == FrameStatus::kLost || status == FrameStatus::kTimeout) {
        drain_ = 0;
        return status;
      }
    }
    return NextAny(frame, timeout_ms);
  }

  FrameStatus NextAny(Frame& frame, int timeout_ms) {
    if (fd_ < 0) {
      // Lost earlier: try to come back, at most twice a second.
      const auto now = std::chrono::steady_clock::now();
      if (now - last_reopen_ < std::chrono::milliseconds(500)) return FrameStatus::kLost;
      last_reopen_ = now;
      std::string why;
      if (!TryOpen(why)) {
        error_ = why;
        return FrameStatus::kLost;
      }
      LogInfo(device_ + ": camera is back");
    }
    pollfd p{fd_, POLLIN, 0};
    const int ready = ::poll(&p, 1, std::max(0, timeout_ms));
    if (ready == 0) return FrameStatus::kTimeout;
    if (ready < 0) {
      if (errno == EINTR) return FrameStatus::kTimeout;
      return Lose(errno);
    }
    if (p.revents & (POLLERR | POLLHUP | POLLNVAL)) return Lose(ENODEV);
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    if (Xioctl(fd_, VIDIOC_DQBUF, &buf) == -1) {
      if (errno == EAGAIN) return FrameStatus::kTimeout;
      return Lose(errno);
    }
    FrameStatus status = FrameStatus::kOk;
    const size_t expected = static_cast<size_t>(width_) * height_ * 3;
    if (buf.index >= buffers_.size() || (buf.flags & V4L2_BUF_FLAG_ERROR) || buf.bytesused < expected) {
      error_ =
          device_ + ": damaged frame (" + std::to_string(buf.bytesused) + " of " + std::to_string(expected) + " bytes)";
      status = FrameStatus::kCorrupt;
    } else {
      frame.image = Image8(width_, height_, 3);
      const auto* src = static_cast<const std::uint8_t*>(buffers_[buf.index].start);
      for (int y = 0; y < height_; ++y)
        std::memcpy(frame.image.Pixel(0, y), src + static_cast<size_t>(y) * stride_, static_cast<size_t>(width_) * 3);
      const bool monotonic = (buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
      frame.t_ns = monotonic ? static_cast<std::int64_t>(buf.timestamp.tv_sec) * 1000000000LL +
                                   static_cast<std::int64_t>(buf.timestamp.tv_usec) * 1000
                             : MonotonicNs();
      frame.index = index_++;
      frame.name.clear();
      frame.T_world_camera_true.reset();
    }
    if (Xioctl(fd_, VIDIOC_QBUF, &buf) == -1) return Lose(errno);
    return status;
  }

  // Exposure brackets: the first call switches auto exposure, auto gain and
  // auto white balance off (held at their current values) for the session;
  // every call drops the frames already queued, which were exposed before
  // the change, so the next frame Next() returns has the new exposure.
  bool SetExposure(double exposure_us) override {
    if (fd_ < 0) return false;
    if (!locked_) {
      std::vector<std::string> failed;
      auto note = [&](const std::string& r) {
        if (!r.empty()) failed.push_back(r);
      };
      note(SetControl(fd_, V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL, "manual exposure"));
      if (HasControl(V4L2_CID_AUTOGAIN)) note(SetControl(fd_, V4L2_CID_AUTOGAIN, 0, "manual gain"));
      if (HasControl(V4L2_CID_AUTO_WHITE_BALANCE)) {
        // Hold the white balance the camera has settled on.
        v4l2_control current{};
        current.id = V4L2_CID_WHITE_BALANCE_TEMPERATURE;
        const bool known = Xioctl(fd_, VIDIOC_G_CTRL, &current) == 0;
        note(SetControl(fd_, V4L2_CID_AUTO_WHITE_BALANCE, 0, "manual white balance"));
        if (known) note(SetControl(fd_, V4L2_CID_WHITE_BALANCE_TEMPERATURE, current.value, "white balance"));
      }
      for (const std::string& f : failed) LogWarning(device_ + ": cannot set " + f);
      LogInfo(device_ + ": auto exposure, gain and white balance locked for the session");
      locked_ = true;
    }
    // V4L2_CID_EXPOSURE_ABSOLUTE counts 100 microsecond units, within the device's range.
    int units = std::max(1, static_cast<int>(std::lround(exposure_us / 100)));
    v4l2_queryctrl range{};
    range.id = V4L2_CID_EXPOSURE_ABSOLUTE;
    if (Xioctl(fd_, VIDIOC_QUERYCTRL, &range) == 0) units = std::clamp(units, range.minimum, range.maximum);
    const std::string failed = SetControl(fd_, V4L2_CID_EXPOSURE_ABSOLUTE, units, "exposure");
    if (!failed.empty()) {
      LogWarning(device_ + ": cannot set " + failed);
      return false;
    }
    // Every queued buffer, and the one the sensor is reading out.
    drain_ = static_cast<int>(buffers_.size()) + 1;
    return true;
  }

  std::string LastError() const override { return error_; }

 private:
  bool HasControl(uint32_t id) const {
    v4l2_queryctrl q{};
    q.id = id;
    return Xioctl(fd_, VIDIOC_QUERYCTRL, &q) == 0 && !(q.flags & V4L2_CTRL_FLAG_DISABLED);
  }

  struct Buffer {
    void* start = MAP_FAILED;
    size_t length = 0;
  };

  FrameStatus Lose(int error) {
    error_ = device_ + ": " + (DeviceGone(error) ? "camera disconnected" : "capture failed") + " (" +
             std::strerror(error) + ")";
    Close();
    last_reopen_ = std::chrono::steady_clock::now();
    return FrameStatus::kLost;
  }

  void Close() {
    if (fd_ < 0) return;
    v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    Xioctl(fd_, VIDIOC_STREAMOFF, &type);
    for (Buffer& b : buffers_)
      if (b.start != MAP_FAILED) v4l2_munmap(b.start, b.length);
    buffers_.clear();
    v4l2_close(fd_);
    fd_ = -1;
  }

  bool Fail(std::string& why, const std::string& what) {
    why = what + (errno ? std::string(" (") + std::strerror(errno) + ")" : "");
    Close();
    return false;
  }

  bool TryOpen(std::string& why) {
    errno = 0;
    fd_ = v4l2_open(device_.c_str(), O_RDWR | O_NONBLOCK, 0);
    if (fd_ < 0) return Fail(why, "cannot open the device (expected a V4L2 camera)");
    v4l2_capability cap{};
    if (Xioctl(fd_, VIDIOC_QUERYCAP, &cap) == -1) return Fail(why, "not a V4L2 device");
    const uint32_t caps = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
    errno = 0;
    if (!(caps & V4L2_CAP_VIDEO_CAPTURE)) return Fail(why, "not a capture device (a metadata or output node?)");
    if (!(caps & V4L2_CAP_STREAMING)) return Fail(why, "does not support streaming I/O (expected mmap streaming)");
    card_ = reinterpret_cast<const char*>(cap.card);

    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (Xioctl(fd_, VIDIOC_G_FMT, &fmt) == -1) return Fail(why, "cannot read the format");
    native_fourcc_ = FourCc(fmt.fmt.pix.pixelformat);
    if (controls_.width > 0) {
      fmt.fmt.pix.width = static_cast<uint32_t>(controls_.width);
      fmt.fmt.pix.height = static_cast<uint32_t>(controls_.height);
    }
    fmt.fmt.pix.pixelformat = V4L2_PIX_FMT_RGB24;  // converted by libv4l2
    fmt.fmt.pix.field = V4L2_FIELD_ANY;
    if (Xioctl(fd_, VIDIOC_S_FMT, &fmt) == -1) return Fail(why, "cannot set the format");
    errno = 0;
    if (fmt.fmt.pix.pixelformat != V4L2_PIX_FMT_RGB24)
      return Fail(why, "libv4l2 cannot convert " + native_fourcc_ + " to RGB24");
    width_ = static_cast<int>(fmt.fmt.pix.width);
    height_ = static_cast<int>(fmt.fmt.pix.height);
    stride_ = std::max<size_t>(fmt.fmt.pix.bytesperline, static_cast<size_t>(width_) * 3);
    if (width_ <= 0 || height_ <= 0 || width_ > kMaxImageSide || height_ > kMaxImageSide)
      return Fail(why, "absurd frame size " + std::to_string(width_) + "x" + std::to_string(height_));
    if (controls_.width > 0 && (width_ != controls_.width || height_ != controls_.height))
      LogWarning(device_ + ": asked for " + std::to_string(controls_.width) + "x" + std::to_string(controls_.height) +
                 ", the camera gives " + std::to_string(width_) + "x" + std::to_string(height_));

    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (controls_.fps > 0) {
      parm.parm.capture.timeperframe = {1000, static_cast<uint32_t>(std::lround(controls_.fps * 1000))};
      if (Xioctl(fd_, VIDIOC_S_PARM, &parm) == -1) LogWarning(device_ + ": cannot set the frame rate");
    }
    if (Xioctl(fd_, VIDIOC_G_PARM, &parm) == 0 && parm.parm.capture.timeperframe.numerator > 0)
      fps_ = static_cast<double>(parm.parm.capture.timeperframe.denominator) / parm.parm.capture.timeperframe.numerator;

    std::vector<std::string> failed;
    auto note = [&](const std::string& r) {
      if (!r.empty()) failed.push_back(r);
    };
    if (controls_.exposure_us > 0) {
      note(SetControl(fd_, V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL, "manual exposure"));
      // V4L2_CID_EXPOSURE_ABSOLUTE counts 100 microsecond units.
      note(SetControl(fd_, V4L2_CID_EXPOSURE_ABSOLUTE,
                      std::max(1, static_cast<int>(std::lround(controls_.exposure_us / 100))), "exposure"));
    }
    if (controls_.gain >= 0)
      note(SetControl(fd_, V4L2_CID_GAIN, static_cast<int>(std::lround(controls_.gain)), "gain"));
    if (controls_.white_balance_k > 0) {
      note(SetControl(fd_, V4L2_CID_AUTO_WHITE_BALANCE, 0, "manual white balance"));
      note(SetControl(fd_, V4L2_CID_WHITE_BALANCE_TEMPERATURE, controls_.white_balance_k, "white balance"));
    }
    for (const std::string& f : failed) LogWarning(device_ + ": cannot set " + f);

    v4l2_requestbuffers req{};
    req.count = static_cast<uint32_t>(controls_.buffers);
    req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    req.memory = V4L2_MEMORY_MMAP;
    if (Xioctl(fd_, VIDIOC_REQBUFS, &req) == -1 || req.count < 2) return Fail(why, "cannot get mmap buffers");
    for (uint32_t i = 0; i < req.count; ++i) {
      v4l2_buffer buf{};
      buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      buf.memory = V4L2_MEMORY_MMAP;
      buf.index = i;
      if (Xioctl(fd_, VIDIOC_QUERYBUF, &buf) == -1) return Fail(why, "cannot query buffer " + std::to_string(i));
      Buffer b;
      b.length = buf.length;
      b.start = v4l2_mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buf.m.offset);
      if (b.start == MAP_FAILED) return Fail(why, "cannot map buffer " + std::to_string(i));
      buffers_.push_back(b);
      if (Xioctl(fd_, VIDIOC_QBUF, &buf) == -1) return Fail(why, "cannot queue buffer " + std::to_string(i));
    }
    v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (Xioctl(fd_, VIDIOC_STREAMON, &type) == -1) return Fail(why, "cannot start streaming");
    return true;
  }

  std::string device_;
  CameraControls controls_;
  int fd_ = -1;
  std::vector<Buffer> buffers_;
  int width_ = 0, height_ = 0;
  size_t stride_ = 0;
  double fps_ = 0;
  std::string card_, native_fourcc_;
  std::int64_t index_ = 0;
  std::string error_;
  std::chrono::steady_clock::time_point last_reopen_{};
  bool locked_ = false;  // AE, auto gain, AWB held since the first SetExposure
  int drain_ = 0;        // frames still to drop after an exposure change
};

std::string Range(const v4l2_queryctrl& q) {
  return std::to_string(q.minimum) + ".." + std::to_string(q.maximum) + " (default " + std::to_string(q.default_value) +
         ")";
}

}  // namespace

namespace detail {
std::unique_ptr<FrameSource> OpenV4l2Source(const std::string& device, const CameraControls& controls) {
  if (device.empty()) ThrowInputError("v4l2:", "no device (expected e.g. v4l2:/dev/video0)");
  std::error_code error;
  if (!std::filesystem::exists(device, error))
    ThrowInputError(device, "no such device (run 'nerfar cameras' to list what is attached)");
  auto source = std::make_unique<V4l2Source>(device, controls);
  source->Open();
  return source;
}
}  // namespace detail

std::vector<CameraInfo> ListV4l2Cameras() {
  std::vector<std::string> devices;
  std::error_code error;
  for (const auto& entry : std::filesystem::directory_iterator("/dev", error)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("video", 0) == 0) devices.push_back(entry.path().string());
  }
  std::sort(devices.begin(), devices.end());
  std::vector<CameraInfo> cameras;
  for (const std::string& device : devices) {
    CameraInfo info;
    info.backend = "v4l2";
    info.source = "v4l2:" + device;
    const int fd = v4l2_open(device.c_str(), O_RDWR | O_NONBLOCK, 0);
    if (fd < 0) {
      info.error = std::string("cannot open (") + std::strerror(errno) + ")";
      cameras.push_back(info);
      continue;
    }
    v4l2_capability cap{};
    if (Xioctl(fd, VIDIOC_QUERYCAP, &cap) == -1) {
      v4l2_close(fd);
      continue;  // not a V4L2 node
    }
    const uint32_t caps = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
    if (!(caps & V4L2_CAP_VIDEO_CAPTURE)) {
      v4l2_close(fd);
      continue;  // metadata or output node of a camera listed elsewhere
    }
    info.name = reinterpret_cast<const char*>(cap.card);
    info.bus = reinterpret_cast<const char*>(cap.bus_info);
    for (uint32_t f = 0; f < 64; ++f) {
      v4l2_fmtdesc desc{};
      desc.index = f;
      desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      if (Xioctl(fd, VIDIOC_ENUM_FMT, &desc) == -1) break;
      CameraFormat format;
      format.fourcc = FourCc(desc.pixelformat);
      format.description = reinterpret_cast<const char*>(desc.description);
      if (desc.flags & V4L2_FMT_FLAG_EMULATED) format.description += " (converted by libv4l2)";
      for (uint32_t s = 0; s < 256; ++s) {
        v4l2_frmsizeenum size{};
        size.index = s;
        size.pixel_format = desc.pixelformat;
        if (Xioctl(fd, VIDIOC_ENUM_FRAMESIZES, &size) == -1) break;
        if (size.type != V4L2_FRMSIZE_TYPE_DISCRETE) {
          format.sizes.push_back(
              std::to_string(size.stepwise.min_width) + "x" + std::to_string(size.stepwise.min_height) + "-" +
              std::to_string(size.stepwise.max_width) + "x" + std::to_string(size.stepwise.max_height) + " (stepwise)");
          break;
        }
        std::string line = std::to_string(size.discrete.width) + "x" + std::to_string(size.discrete.height);
        std::string rates;
        for (uint32_t r = 0; r < 32; ++r) {
          v4l2_frmivalenum ival{};
          ival.index = r;
          ival.pixel_format = desc.pixelformat;
          ival.width = size.discrete.width;
          ival.height = size.discrete.height;
          if (Xioctl(fd, VIDIOC_ENUM_FRAMEINTERVALS, &ival) == -1 || ival.type != V4L2_FRMIVAL_TYPE_DISCRETE) break;
          if (ival.discrete.numerator == 0) continue;
          const double fps = static_cast<double>(ival.discrete.denominator) / ival.discrete.numerator;
          rates += (rates.empty() ? " @" : ",") + std::to_string(static_cast<int>(std::lround(fps)));
        }
        format.sizes.push_back(line + rates);
      }
      info.formats.push_back(format);
    }
    const std::pair<uint32_t, const char*> kControls[] = {
        {V4L2_CID_EXPOSURE_AUTO, "exposure_auto"},
        {V4L2_CID_EXPOSURE_ABSOLUTE, "exposure_absolute (100 us)"},
        {V4L2_CID_GAIN, "gain"},
        {V4L2_CID_AUTO_WHITE_BALANCE, "white_balance_auto"},
        {V4L2_CID_WHITE_BALANCE_TEMPERATURE, "white_balance_temperature (K)"},
    };
    for (const auto& [id, name] : kControls) {
      v4l2_queryctrl q{};
      q.id = id;
      if (Xioctl(fd, VIDIOC_QUERYCTRL, &q) == 0 && !(q.flags & V4L2_CTRL_FLAG_DISABLED))
        info.controls.push_back(std::string(name) + " " + Range(q));
    }
    v4l2_close(fd);
    cameras.push_back(info);
  }
  return cameras;
}

}  // namespace nerfar

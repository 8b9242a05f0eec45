#include "calib/core/exr.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <half.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <filesystem>
#include <stdexcept>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"

namespace nerfar {
namespace {

// Opens the file with OpenEXR and runs `body`; every OpenEXR exception becomes
// an InputError naming the path.
template <typename Body>
auto WithExrInput(const std::string& path, Body body) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) ThrowInputError(path, "no such file (expected an EXR image)");
  try {
    Imf::InputFile file(path.c_str());
    return body(file);
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    ThrowInputError(path, std::string("not a readable OpenEXR file (") + e.what() + ")");
  }
}

struct Window {
  int x0, y0, width, height;
};

Window CheckedWindow(const std::string& path, const Imf::Header& header) {
  const Imath::Box2i box = header.dataWindow();
  const long long width = static_cast<long long>(box.max.x) - box.min.x + 1;
  const long long height = static_cast<long long>(box.max.y) - box.min.y + 1;
  if (width < 1 || height < 1 || width > kMaxImageSide || height > kMaxImageSide || width * height > kMaxImagePixels)
    ThrowInputError(path, "image is " + std::to_string(width) + "x" + std::to_string(height) + " (expected 1.." +
                              std::to_string(kMaxImageSide) + " per side, at most " + std::to_string(kMaxImagePixels) +
                              " pixels)");
  return {box.min.x, box.min.y, static_cast<int>(width), static_cast<int>(height)};
}

ImageF ReadChannels(const std::string& path, Imf::InputFile& file, const std::vector<std::string>& channels) {
  const Imf::Header& header = file.header();
  const Window window = CheckedWindow(path, header);
  if (channels.empty() || channels.size() > static_cast<size_t>(kMaxImageChannels))
    ThrowInputError(path, "asked for " + std::to_string(channels.size()) + " channels (expected 1..64)");
  Problems problems(path);
  for (const std::string& name : channels) {
    const Imf::Channel* channel = header.channels().findChannel(name);
    if (channel == nullptr) {
      problems.Add("", "missing channel '" + name + "'");
    } else if (channel->xSampling != 1 || channel->ySampling != 1) {
      problems.Add("", "channel '" + name + "' is subsampled (expected full resolution)");
    }
  }
  problems.ThrowIfAny();

  // A frame buffer holds each channel name once: read the distinct names, then
  // replicate (e.g. Y,Y,Y for grey read as colour).
  std::vector<std::string> distinct;
  for (const std::string& name : channels)
    if (std::find(distinct.begin(), distinct.end(), name) == distinct.end()) distinct.push_back(name);
  if (distinct.size() != channels.size()) {
    const ImageF unique = ReadChannels(path, file, distinct);
    ImageF image(unique.width, unique.height, static_cast<int>(channels.size()));
    for (size_t c = 0; c < channels.size(); ++c) {
      const size_t source =
          static_cast<size_t>(std::find(distinct.begin(), distinct.end(), channels[c]) - distinct.begin());
      for (size_t p = 0; p < image.PixelCount(); ++p)
        image.pixels[p * image.channels + c] = unique.pixels[p * unique.channels + source];
    }
    return image;
  }

  ImageF image(window.width, window.height, static_cast<int>(channels.size()));
  Imf::FrameBuffer frame_buffer;
  const size_t x_stride = sizeof(float) * image.channels;
  const size_t y_stride = x_stride * image.width;
  // OpenEXR addresses the buffer by absolute data-window coordinates.
  char* origin = reinterpret_cast<char*>(image.pixels.data()) -
                 static_cast<ptrdiff_t>(window.x0) * static_cast<ptrdiff_t>(x_stride) -
                 static_cast<ptrdiff_t>(window.y0) * static_cast<ptrdiff_t>(y_stride);
  for (size_t c = 0; c < channels.size(); ++c)
    frame_buffer.insert(channels[c], Imf::Slice(Imf::FLOAT, origin + c * sizeof(float), x_stride, y_stride));
  file.setFrameBuffer(frame_buffer);
  file.readPixels(window.y0, window.y0 + window.height - 1);

  const auto bad = std::find_if(image.pixels.begin(), image.pixels.end(), [](float v) { return !std::isfinite(v); });
  if (bad != image.pixels.end()) {
    const size_t index = static_cast<size_t>(bad - image.pixels.begin()) / image.channels;
    const size_t count = static_cast<size_t>(
        std::count_if(image.pixels.begin(), image.pixels.end(), [](float v) { return !std::isfinite(v); }));
    ThrowInputError(path, std::to_string(count) + " non-finite values, first at pixel (" +
                              std::to_string(index % image.width) + ", " + std::to_string(index / image.width) +
                              ") (expected finite radiance)");
  }
  return image;
}

bool FitsHalf(const std::vector<float>& values) {
  const float largest = HALF_MAX;
  return std::all_of(values.begin(), values.end(), [largest](float v) { return !(std::abs(v) > largest); });
}

std::vector<std::string> ChannelNames(const Imf::Header& header) {
  std::vector<std::string> names;
  for (auto it = header.channels().begin(); it != header.channels().end(); ++it) names.emplace_back(it.name());
  return names;
}

}  // namespace

std::vector<std::string> ReadExrChannelNames(const std::string& path) {
  return WithExrInput(path, [](Imf::InputFile& file) { return ChannelNames(file.header()); });
}

ImageF ReadExr(const std::string& path, const std::vector<std::string>& channels) {
  return WithExrInput(path, [&](Imf::InputFile& file) { return ReadChannels(path, file, channels); });
}

ImageF ReadExrRgb(const std::string& path) {
  return WithExrInput(path, [&](Imf::InputFile& file) {
    const Imf::ChannelList& list = file.header().channels();
    if (list.findChannel("R") && list.findChannel("G") && list.findChannel("B"))
      return ReadChannels(path, file, {"R", "G", "B"});
    if (list.findChannel("Y")) return ReadChannels(path, file, {"Y", "Y", "Y"});
    ThrowInputError(path, "has no R, G, B or Y channels (expected a colour image)");
  });
}

ImageF ReadExrChannel(const std::string& path, const std::string& channel) {
  return WithExrInput(path, [&](Imf::InputFile& file) {
    if (!channel.empty()) return ReadChannels(path, file, {channel});
    const std::vector<std::string> names = ChannelNames(file.header());
    if (names.size() != 1)
      ThrowInputError(path, "has " + std::to_string(names.size()) + " channels (expected exactly one)");
    return ReadChannels(path, file, names);
  });
}

void WriteExr(const std::string& path, const ImageF& image, const std::vector<std::string>& names, ExrPixelType type) {
  NERFAR_CHECK_EQ(static_cast<size_t>(image.channels), names.size());
  NERFAR_CHECK_EQ(image.pixels.size(), image.PixelCount() * image.channels);
  NERFAR_CHECK(image.width > 0 && image.height > 0);
  // A value beyond half's range would become ±inf, which no reader takes back.
  if (type == ExrPixelType::kHalf && !FitsHalf(image.pixels)) type = ExrPixelType::kFloat;
  const Imf::PixelType pixel_type = type == ExrPixelType::kHalf ? Imf::HALF : Imf::FLOAT;
  Imf::Header header(image.width, image.height);
  header.compression() = Imf::ZIP_COMPRESSION;
  for (const std::string& name : names) header.channels().insert(name, Imf::Channel(pixel_type));

  // OpenEXR writes only from a buffer of the file's own pixel type, so half
  // output is converted here (round to nearest, overflow to ±inf like any cast).
  std::vector<half> halves;
  char* base = nullptr;
  size_t element = sizeof(float);
  if (type == ExrPixelType::kHalf) {
    halves.assign(image.pixels.begin(), image.pixels.end());
    base = reinterpret_cast<char*>(halves.data());
    element = sizeof(half);
  } else {
    // OpenEXR wants a non-const base pointer even for writing; it does not write.
    base = const_cast<char*>(reinterpret_cast<const char*>(image.pixels.data()));
  }
  Imf::FrameBuffer frame_buffer;
  const size_t x_stride = element * image.channels;
  const size_t y_stride = x_stride * image.width;
  for (size_t c = 0; c < names.size(); ++c)
    frame_buffer.insert(names[c], Imf::Slice(pixel_type, base + c * element, x_stride, y_stride));

  AtomicFile out(path);
  try {
    Imf::OutputFile file(out.temp_path().c_str(), header);
    file.setFrameBuffer(frame_buffer);
    file.writePixels(image.height);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot write EXR (" + e.what() + ")");
  }
  out.Commit();
}

void WriteExrRgb(const std::string& path, const ImageF& image, ExrPixelType type) {
  NERFAR_CHECK(image.channels == 3 || image.channels == 4);
  if (image.channels == 3) {
    WriteExr(path, image, {"R", "G", "B"}, type);
  } else {
    WriteExr(path, image, {"R", "G", "B", "A"}, type);
  }
}

}  // namespace nerfar

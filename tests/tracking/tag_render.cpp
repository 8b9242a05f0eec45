#include "tests/tracking/tag_render.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "calib/core/image_io.h"
#include "tracking/tag_detector.h"

namespace nerfar::testing {

Board GridBoard(int rows, int cols, double tag_size_m, double pitch_m) {
  Board board;
  board.family = "tag36h11";
  board.tag_size_m = tag_size_m;
  int id = 0;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      BoardTag tag;
      tag.id = id++;
      tag.center = {(c - 0.5 * (cols - 1)) * pitch_m, (0.5 * (rows - 1) - r) * pitch_m, 0.0};
      tag.up_direction = {0, 1, 0};
      const double h = 0.5 * tag_size_m;
      // TL, TR, BR, BL of the printed tag read upright (up = +y, right = +x).
      tag.corners = {tag.center + Vec3{-h, h, 0}, tag.center + Vec3{h, h, 0}, tag.center + Vec3{h, -h, 0},
                     tag.center + Vec3{-h, -h, 0}};
      board.tags.push_back(tag);
    }
  return board;
}

namespace {

struct TagPaint {
  Vec3 origin, x_axis, y_axis;  // TL corner; unit axes along the top and left edges
  double cell = 0;
  Image8 bitmap;  // with its 1-cell white border
};

// Linear radiance of the board plane at world point p.
double Albedo(const std::vector<TagPaint>& tags, const RenderOptions& o, const Vec3& p) {
  for (const TagPaint& t : tags) {
    const Vec3 d = p - t.origin;
    const double u = Dot(d, t.x_axis) / t.cell, v = Dot(d, t.y_axis) / t.cell;  // cells from TL corner
    const int border = 1;                                                       // the bitmap's white ring
    const int n = t.bitmap.width - 2 * border;
    if (u < -o.paper_margin_cells || v < -o.paper_margin_cells || u >= n + o.paper_margin_cells ||
        v >= n + o.paper_margin_cells)
      continue;
    const int i = static_cast<int>(std::floor(u)) + border, j = static_cast<int>(std::floor(v)) + border;
    if (i < 0 || j < 0 || i >= t.bitmap.width || j >= t.bitmap.height) return o.paper;
    return t.bitmap.at(i, j) < 128 ? o.ink : o.paper;
  }
  return o.table;
}

ImageF RenderLinear(const Board& board, const CameraIntrinsics& camera, const Pose& T_world_camera,
                    const RenderOptions& o) {
  std::vector<TagPaint> tags;
  const int cells = TagBlackSquareCells(board.family);
  for (const BoardTag& bt : board.tags) {
    TagPaint t;
    t.origin = bt.corners[0];
    t.x_axis = Normalized(bt.corners[1] - bt.corners[0]);
    t.y_axis = Normalized(bt.corners[3] - bt.corners[0]);
    t.cell = board.tag_size_m / cells;
    t.bitmap = TagBitmap(board.family, bt.id);
    tags.push_back(std::move(t));
  }
  const Vec3 plane_point = board.tags.front().corners[0];
  const Vec3 normal = Normalized(Cross(board.tags.front().corners[1] - board.tags.front().corners[0],
                                       board.tags.front().corners[3] - board.tags.front().corners[0]));
  const Vec3 center = T_world_camera.translation;
  ImageF out(camera.width, camera.height, 1);
  const int s = o.supersample;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      double sum = 0;
      for (int sy = 0; sy < s; ++sy)
        for (int sx = 0; sx < s; ++sx) {
          const Vec2 pixel{x + (sx + 0.5) / s, y + (sy + 0.5) / s};
          const Vec3 ray = T_world_camera.Rotate(Unproject(camera, pixel));
          const double denom = Dot(ray, normal);
          double value = 0;  // background: nothing
          if (std::abs(denom) > 1e-12) {
            const double t = Dot(plane_point - center, normal) / denom;
            if (t > 0) value = Albedo(tags, o, center + ray * t);
          }
          sum += value;
        }
      out.at(x, y) = static_cast<float>(sum / (s * s));
    }
  return out;
}

Image8 Finish(const ImageF& linear, const RenderOptions& o) {
  cv::Mat m(linear.height, linear.width, CV_32F, const_cast<float*>(linear.pixels.data()));
  cv::Mat work = m.clone();
  if (o.blur_sigma > 0) cv::GaussianBlur(work, work, cv::Size(), o.blur_sigma);
  std::mt19937 rng(o.seed);
  std::normal_distribution<double> noise(0.0, o.noise_sigma);
  Image8 image(linear.width, linear.height, 1);
  for (int y = 0; y < linear.height; ++y)
    for (int x = 0; x < linear.width; ++x) {
      double v = 255.0 * LinearToSrgb(static_cast<float>(std::min(1.0, work.at<float>(y, x) * o.gain)));
      if (o.noise_sigma > 0) v += noise(rng);
      if (x >= o.occlude_x0 && x < o.occlude_x1 && y >= o.occlude_y0 && y < o.occlude_y1) v = 60;
      image.at(x, y) = static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
    }
  return image;
}

}  // namespace

Image8 RenderBoard(const Board& board, const CameraIntrinsics& camera, const Pose& T_world_camera,
                   const RenderOptions& options) {
  return Finish(RenderLinear(board, camera, T_world_camera, options), options);
}

Image8 RenderMotionBlur(const Board& board, const CameraIntrinsics& camera, const Pose& from, const Pose& to, int steps,
                        const RenderOptions& options) {
  ImageF sum(camera.width, camera.height, 1);
  const Vec3 w = AxisAngleFromRotation(to.rotation * from.rotation.Transposed());
  for (int k = 0; k < steps; ++k) {
    const double f = steps > 1 ? static_cast<double>(k) / (steps - 1) : 0.0;
    const double angle = Length(w) * f;
    const Pose pose{angle > 0 ? RotationFromAxisAngle(w, angle) * from.rotation : from.rotation,
                    from.translation + (to.translation - from.translation) * f};
    const ImageF one = RenderLinear(board, camera, pose, options);
    for (size_t i = 0; i < sum.pixels.size(); ++i) sum.pixels[i] += one.pixels[i] / steps;
  }
  return Finish(sum, options);
}

Pose LookAt(const Vec3& target, double distance_m, double elevation_rad, double azimuth_rad) {
  const Vec3 offset{std::cos(elevation_rad) * std::cos(azimuth_rad), std::cos(elevation_rad) * std::sin(azimuth_rad),
                    std::sin(elevation_rad)};
  const Vec3 center = target + offset * distance_m;
  const Vec3 z = Normalized(target - center);    // forward
  Vec3 x = Normalized(Cross(z, Vec3{0, 0, 1}));  // right
  if (Length(x) < 0.5) x = {1, 0, 0};            // looking straight down
  const Vec3 y = Cross(z, x);                    // down
  return {Mat3::FromColumns(x, y, z), center};
}

CameraIntrinsics TestCamera(int width, int height, double hfov_deg) {
  CameraIntrinsics c;
  c.width = width;
  c.height = height;
  c.fx = c.fy = 0.5 * width / std::tan(0.5 * hfov_deg * kPi / 180.0);
  c.cx = 0.5 * width;
  c.cy = 0.5 * height;
  return c;
}

}  // namespace nerfar::testing

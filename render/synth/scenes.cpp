#include "render/synth/scenes.h"

// image_u8.h lacks C linkage guards; wrap the C headers.
extern "C" {
#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag36h11.h>
}

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>

#include "calib/core/error.h"
#include "calib/core/random.h"

namespace nerfar::synth {

namespace {

constexpr double kDeg = kPi / 180.0;

Vec3f F(const Vec3& v) { return Vec3f(v); }

// One tag36h11 bitmap as printed (row 0 at the top), 10 x 10 cells: the
// family's one-cell white ring, the black border and the 6 x 6 data cells.
// true = white.
std::vector<bool> TagBitmap(int id, int& size) {
  std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)> family(tag36h11_create(), tag36h11_destroy);
  NERFAR_CHECK(family != nullptr);
  NERFAR_CHECK_LT(static_cast<uint32_t>(id), family->ncodes);
  image_u8_t* image = apriltag_to_image(family.get(), id);
  NERFAR_CHECK(image != nullptr);
  size = image->width;
  NERFAR_CHECK_EQ(image->width, image->height);
  std::vector<bool> bits(static_cast<size_t>(size) * size);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) bits[static_cast<size_t>(y) * size + x] = image->buf[y * image->stride + x] > 127;
  // image_u8_destroy is not exported by the shared library; it frees these two blocks.
  std::free(image->buf);
  std::free(image);
  return bits;
}

// Smooth value noise in [0, 1] on a lattice of period 1, seeded.
float ValueNoise(uint64_t seed, float x, float y) {
  const int xi = static_cast<int>(std::floor(x)), yi = static_cast<int>(std::floor(y));
  const float fx = x - xi, fy = y - yi;
  auto lattice = [seed](int i, int j) {
    return static_cast<float>(
               Mix64(seed ^ Mix64(static_cast<uint64_t>(i) * 0x100000001b3ull + static_cast<uint32_t>(j))) >> 40) *
           0x1.0p-24f;
  };
  const float sx = fx * fx * (3 - 2 * fx), sy = fy * fy * (3 - 2 * fy);
  const float a = lattice(xi, yi) + (lattice(xi + 1, yi) - lattice(xi, yi)) * sx;
  const float b = lattice(xi, yi + 1) + (lattice(xi + 1, yi + 1) - lattice(xi, yi + 1)) * sx;
  return a + (b - a) * sy;
}

// Wood-like table top, 1 mm texels: grain along x with ring stripes.
PlanarTexture WoodTexture(uint64_t seed) {
  PlanarTexture tex;
  const int w = 1200, h = 800;
  tex.image = ImageF(w, h, 3);
  tex.origin = {-0.6f, -0.4f, 0.0f};
  tex.u_axis = {1, 0, 0};
  tex.v_axis = {0, 1, 0};
  tex.size_u = 1.2f;
  tex.size_v = 0.8f;
  const Vec3f base{0.46f, 0.30f, 0.17f};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float wx = x * 0.001f, wy = y * 0.001f;
      const float warp = 2.0f * ValueNoise(seed, wx * 4.0f, wy * 25.0f) + 0.5f * ValueNoise(seed + 1, wx * 30, wy * 80);
      const float rings = 0.5f + 0.5f * std::sin(2.0f * static_cast<float>(kPi) * (wy * 45.0f + warp));
      const float fine = ValueNoise(seed + 2, wx * 300.0f, wy * 900.0f);
      const float k = 0.78f + 0.22f * rings + 0.08f * (fine - 0.5f);
      float* p = tex.image.Pixel(x, y);
      p[0] = std::clamp(base.x * k, 0.0f, 1.0f);
      p[1] = std::clamp(base.y * k, 0.0f, 1.0f);
      p[2] = std::clamp(base.z * k * 0.95f, 0.0f, 1.0f);
    }
  return tex;
}

struct TagLayout {
  int id;
  double x, y, yaw_deg;
};

// Positions and yaw as in ../shared/scenes/*/board.json: 4 tags along each
// long edge, 2 along each short edge, counter-clockwise from (-0.45, -0.33),
// printed 'up' pointing away from the table centre.
constexpr TagLayout kTagLayout[] = {
    {0, -0.45, -0.33, 180}, {1, -0.15, -0.33, 180}, {2, 0.15, -0.33, 180}, {3, 0.45, -0.33, 180},
    {4, 0.53, -0.12, -90},  {5, 0.53, 0.12, -90},   {6, 0.45, 0.33, 0},    {7, 0.15, 0.33, 0},
    {8, -0.15, 0.33, 0},    {9, -0.45, 0.33, 0},    {10, -0.53, 0.12, 90}, {11, -0.53, -0.12, 90},
};

Vec3 TagUp(double yaw_deg) { return {-std::sin(yaw_deg * kDeg), std::cos(yaw_deg * kDeg), 0.0}; }
// The printed image's right direction: up x (0, 0, 1).
Vec3 TagRight(const Vec3& up) { return Cross(up, Vec3{0, 0, 1}); }

void AddTagMat(Scene& scene) {
  const double sheet = kTagSize + 2 * kTagMargin;
  for (const TagLayout& t : kTagLayout) {
    int size = 0;
    const std::vector<bool> bits = TagBitmap(t.id, size);
    // Sheet texture: the bitmap's cells plus one more white cell on each side,
    // so the white margin is 2 cells (15 mm) around the 8-cell black square.
    const int cells = size + 2;
    PlanarTexture tex;
    tex.image = ImageF(cells, cells, 3, kPaperAlbedo);
    // Printed upright as board.json means it (OpenCV aruco's DICT_APRILTAG_36h11
    // corner order, which the shared scenes follow): that is libapriltag's
    // apriltag_to_image() bitmap turned by 180 degrees (checked by detecting
    // tags in the shared scenes and in our renders, tests/synth).
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x)
        if (!bits[static_cast<size_t>(size - 1 - y) * size + (size - 1 - x)])
          for (int c = 0; c < 3; ++c) tex.image.at(x + 1, y + 1, c) = kInkAlbedo;
    NERFAR_CHECK_EQ(cells * kTagSize / 8.0, sheet);  // 12 cells of 7.5 mm
    const Vec3 up = TagUp(t.yaw_deg), right = TagRight(up);
    const Vec3 center{t.x, t.y, kTagSheetZ};
    tex.origin = F(center - right * (sheet / 2) + up * (sheet / 2));
    tex.u_axis = F(right);
    tex.v_axis = F(-up);
    tex.size_u = tex.size_v = static_cast<float>(sheet);
    scene.textures.push_back(std::move(tex));
    SurfaceMaterial m;
    m.albedo = {1, 1, 1};
    m.texture = static_cast<int>(scene.textures.size()) - 1;
    RectangleShape r;
    r.center = F(center);
    r.u_axis = F(right);
    r.v_axis = F(up);  // normal right x up = +z
    r.half_u = r.half_v = static_cast<float>(sheet / 2);
    r.material = scene.AddMaterial(m);
    scene.rectangles.push_back(r);
  }
}

void AddTable(Scene& scene, uint64_t seed) {
  scene.textures.push_back(WoodTexture(seed));
  SurfaceMaterial wood;
  wood.albedo = {1, 1, 1};
  wood.texture = static_cast<int>(scene.textures.size()) - 1;
  scene.boxes.push_back({{0, 0, -0.02f}, {0.6f, 0.4f, 0.02f}, 0.0f, scene.AddMaterial(wood), -1});
}

int DarkMaterial(Scene& scene) {
  SurfaceMaterial m;
  m.albedo = {0.04f, 0.04f, 0.045f};
  return scene.AddMaterial(m);
}

// A dark pole with a round base from the table up to height `top`.
void AddPole(Scene& scene, double x, double y, double top) {
  const int dark = DarkMaterial(scene);
  scene.cylinders.push_back({{static_cast<float>(x), static_cast<float>(y), 0}, 0.045f, 0.012f, dark, -1});
  scene.cylinders.push_back(
      {{static_cast<float>(x), static_cast<float>(y), 0.012f}, 0.005f, static_cast<float>(top - 0.012), dark, -1});
}

// Footprints (x, y, radius) already taken on the table, to keep things apart.
struct Footprint {
  double x, y, r;
};

bool Free(const std::vector<Footprint>& taken, double x, double y, double r, double gap) {
  for (const Footprint& f : taken)
    if (std::hypot(f.x - x, f.y - y) < f.r + r + gap) return false;
  return true;
}

// Lambertian boxes, spheres and cylinders in the middle of the table.
void AddClutter(Scene& scene, Rng& rng, std::vector<Footprint>& taken) {
  const Vec3f palette[] = {{0.75f, 0.20f, 0.15f}, {0.20f, 0.45f, 0.75f}, {0.85f, 0.75f, 0.25f},
                           {0.25f, 0.65f, 0.30f}, {0.70f, 0.70f, 0.72f}, {0.55f, 0.30f, 0.60f}};
  const int kinds[] = {0, 1, 2, 0, 2};  // box, sphere, cylinder, box, cylinder
  int colour = static_cast<int>(rng.Uniform(0, 6));
  for (int kind : kinds) {
    for (int attempt = 0; attempt < 200; ++attempt) {
      const double size = rng.Uniform(0.035, 0.07);  // half extent / radius
      const double r = kind == 0 ? size * std::sqrt(2.0) : size;
      const double x = rng.Uniform(-0.40 + r, 0.40 - r), y = rng.Uniform(-0.26 + r, 0.26 - r);
      if (!Free(taken, x, y, r, 0.03)) continue;
      SurfaceMaterial m;
      m.albedo = palette[colour++ % 6];
      const int mat = scene.AddMaterial(m);
      const float fx = static_cast<float>(x), fy = static_cast<float>(y), fs = static_cast<float>(size);
      if (kind == 0) {
        const float height = static_cast<float>(rng.Uniform(0.5, 1.6)) * fs;
        scene.boxes.push_back(
            {{fx, fy, height}, {fs, fs * 0.8f, height}, static_cast<float>(rng.Uniform(0, kPi)), mat, -1});
      } else if (kind == 1) {
        scene.spheres.push_back({{fx, fy, fs}, fs, mat, -1});
      } else {
        scene.cylinders.push_back({{fx, fy, 0}, fs * 0.8f, static_cast<float>(rng.Uniform(1.5, 3.5)) * fs, mat, -1});
      }
      taken.push_back({x, y, r});
      break;
    }
  }
}

TriangleMesh RotatedAboutX(const TriangleMesh& mesh, double angle_rad) {
  Pose pose;
  pose.rotation = RotationFromAxisAngle({1, 0, 0}, angle_rad);
  return TransformMesh(mesh, pose);
}

// The two virtual objects: a glossy metal sphere (as in the shared scenes) and
// an upright diffuse torus (a mesh with a hole: shadows with a bright centre).
void AddInsertObjects(SynthScene& out, Rng& rng, std::vector<Footprint>& taken) {
  InsertObject sphere;
  sphere.name = "sphere_glossy";
  sphere.mesh = MakeUvSphere(0.05, 64, 32);
  sphere.material.albedo = {0.9, 0.9, 0.9};
  sphere.material.roughness = 0.25;
  sphere.material.metallic = 1.0;
  sphere.material.mesh = "sphere_glossy.obj";
  InsertObject torus;
  torus.name = "torus_diffuse";
  torus.mesh = RotatedAboutX(MakeTorus(0.038, 0.014, 64, 24), kPi / 2);
  torus.material.albedo = {0.8, 0.35, 0.2};
  torus.material.roughness = 0.7;
  torus.material.metallic = 0.0;
  torus.material.mesh = "torus_diffuse.obj";
  for (InsertObject* object : {&sphere, &torus}) {
    const Bounds b = ComputeBounds(object->mesh);
    const double half_height = 0.5 * (b.max.z - b.min.z);
    const double radius = 0.5 * std::hypot(b.max.x - b.min.x, b.max.y - b.min.y);
    for (int attempt = 0;; ++attempt) {
      NERFAR_CHECK_LT(attempt, 2000);
      const double x = rng.Uniform(-0.3, 0.3), y = rng.Uniform(-0.18, 0.18);
      // Close to (but not touching) other objects: within 2-10 cm of one of them.
      if (!Free(taken, x, y, radius, 0.02)) continue;
      if (attempt < 1500 && Free(taken, x, y, radius, 0.10)) continue;
      const double yaw = rng.Uniform(-kPi, kPi);
      object->placement.T_world_object.rotation = RotationFromAxisAngle({0, 0, 1}, yaw);
      object->placement.T_world_object.translation = {x, y, half_height};
      object->placement.center_world = Vec3{x, y, half_height};
      taken.push_back({x, y, radius});
      break;
    }
  }
  out.objects.push_back(std::move(sphere));
  out.objects.push_back(std::move(torus));
}

void AddBulb(Scene& scene, std::vector<Footprint>& taken, double x, double y) {
  const double height = 0.36, radius = 0.03;
  scene.AddSphereLight({{static_cast<float>(x), static_cast<float>(y), static_cast<float>(height)},
                        static_cast<float>(radius),
                        {140.0f, 118.0f, 85.0f}});
  AddPole(scene, x, y, height - radius);
  taken.push_back({x, y, 0.05});
}

ImageF RasterizeSky(const SkyWithWindow& sky, int width, int height, int supersample) {
  ImageF map(width, height, 3);
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) {
      Vec3 sum{0, 0, 0};
      for (int a = 0; a < supersample; ++a)
        for (int b = 0; b < supersample; ++b)
          sum += sky.Radiance(
              EquirectDirection((i + (b + 0.5) / supersample) / width, (j + (a + 0.5) / supersample) / height));
      sum = sum / static_cast<double>(supersample * supersample);
      float* p = map.Pixel(i, j);
      p[0] = static_cast<float>(sum.x);
      p[1] = static_cast<float>(sum.y);
      p[2] = static_cast<float>(sum.z);
    }
  return map;
}

}  // namespace

Vec3 SkyWithWindow::Radiance(const Vec3& d) const {
  const double azimuth = std::atan2(d.y, d.x) / kDeg, elevation = std::asin(std::clamp(d.z, -1.0, 1.0)) / kDeg;
  double delta = std::fmod(azimuth - window_azimuth_deg, 360.0);
  if (delta > 180) delta -= 360;
  if (delta < -180) delta += 360;
  if (std::fabs(delta) <= window_width_deg / 2 && elevation >= window_elev_min_deg && elevation <= window_elev_max_deg)
    return window_radiance;
  if (d.z < 0) return ground;
  return horizon + (zenith - horizon) * std::sqrt(d.z);
}

std::vector<std::string> SynthSceneNames() { return {"lamps", "window", "sun"}; }

Board MakeTagBoard() {
  Board board;
  board.family = "tag36h11";
  board.tag_size_m = kTagSize;
  const double h = kTagSize / 2;
  for (const TagLayout& t : kTagLayout) {
    BoardTag tag;
    tag.id = t.id;
    const Vec3 up = TagUp(t.yaw_deg), right = TagRight(up);
    tag.center = {t.x, t.y, kTagSheetZ};
    tag.up_direction = up;
    // Top-left, top-right, bottom-right, bottom-left of the printed image.
    tag.corners = {tag.center - right * h + up * h, tag.center + right * h + up * h, tag.center + right * h - up * h,
                   tag.center - right * h - up * h};
    board.tags.push_back(tag);
  }
  return board;
}

Scene MakeTabletop(uint64_t seed) {
  Scene scene;
  AddTable(scene, seed);
  AddTagMat(scene);
  return scene;
}

SynthScene MakeSynthScene(const std::string& name, uint64_t seed) {
  const std::vector<std::string> names = SynthSceneNames();
  if (std::find(names.begin(), names.end(), name) == names.end()) {
    std::string known;
    for (const std::string& n : names) known += (known.empty() ? "" : ", ") + n;
    ThrowInputError("scene '" + name + "'", "unknown scene (expected one of: " + known + ")");
  }
  SynthScene out;
  out.name = name;
  out.seed = seed;
  out.board = MakeTagBoard();
  Rng rng(Mix64(seed) ^ std::hash<std::string>{}(name));
  out.scene = MakeTabletop(seed);
  Scene& scene = out.scene;
  std::vector<Footprint> taken;
  if (name == "lamps") {
    AddBulb(scene, taken, -0.23 + rng.Uniform(-0.03, 0.03), 0.05 + rng.Uniform(-0.03, 0.03));
    // Panel: 12 x 8 cm at 28 cm, tilted 35 deg from facing straight down, towards the table centre.
    const double px = 0.20 + rng.Uniform(-0.03, 0.03), py = -0.04 + rng.Uniform(-0.03, 0.03);
    const Vec3 to_centre = Normalized(Vec3{-px, -py, 0});
    const double tilt = 35 * kDeg;
    const Vec3 n = Normalized(to_centre * std::sin(tilt) + Vec3{0, 0, -std::cos(tilt)});
    const Vec3 v = Normalized(Vec3{0, 0, 1} - n * n.z);
    const Vec3 u = Cross(v, n);
    scene.AddRectangleLight({{static_cast<float>(px), static_cast<float>(py), 0.28f},
                             F(u),
                             F(v),
                             0.06f,
                             0.04f,
                             {38.0f, 44.0f, 52.0f},
                             false});
    AddPole(scene, px - n.x * 0.02, py - n.y * 0.02, 0.28 - 0.04 * std::sin(tilt) - 0.002);
    taken.push_back({px, py, 0.07});
    out.description = "bulb (sphere light) and panel (front-emitting rectangle) on dark poles; no environment";
  } else if (name == "window") {
    SkyWithWindow sky;
    sky.window_azimuth_deg = rng.Uniform(25, 65);
    scene.environment.map = RasterizeSky(sky, 512, 256, 4);
    out.sky = sky;
    const double cx = -0.355 + rng.Uniform(-0.02, 0.02), cy = 0.113 + rng.Uniform(-0.02, 0.02);
    scene.AddBoxLight({{static_cast<float>(cx), static_cast<float>(cy), 0.015f},
                       {0.015f, 0.015f, 0.015f},
                       static_cast<float>(rng.Uniform(0, kPi / 2)),
                       {9.0f, 4.5f, 1.5f}});
    taken.push_back({cx, cy, 0.03});
    out.description = "hidden distant light: sky gradient plus a bright window patch; a glowing cube on the table";
  } else {  // sun
    const double sun_azimuth = rng.Uniform(-kPi, kPi), sun_elevation = rng.Uniform(35, 60) * kDeg;
    const Vec3 sun{std::cos(sun_elevation) * std::cos(sun_azimuth), std::cos(sun_elevation) * std::sin(sun_azimuth),
                   std::sin(sun_elevation)};
    scene.environment.lobes.push_back({{0, 0, 1}, 1.5f, {0.35f, 0.45f, 0.6f}});
    scene.environment.lobes.push_back({F(sun), 400.0f, {900.0f, 820.0f, 700.0f}});
    scene.environment.lobes.push_back({F(Normalized(Vec3{-sun.x, -sun.y, 0.3})), 4.0f, {0.3f, 0.25f, 0.2f}});
    AddBulb(scene, taken, -0.25 + rng.Uniform(-0.03, 0.03), 0.08 + rng.Uniform(-0.03, 0.03));
    out.description = "SG environment (sky, sharp sun, bounce lobe) plus a bulb on a pole";
  }
  AddClutter(scene, rng, taken);
  AddInsertObjects(out, rng, taken);
  scene.Build();
  return out;
}

Scene SceneWithObject(const SynthScene& synth, int k) {
  NERFAR_CHECK(k >= 0 && k < static_cast<int>(synth.objects.size()));
  const InsertObject& object = synth.objects[k];
  Scene scene = synth.scene.Copy();
  SurfaceMaterial m;
  m.glossy = true;
  m.albedo = Vec3f(object.material.albedo);
  m.roughness = static_cast<float>(object.material.roughness);
  m.metallic = static_cast<float>(object.material.metallic);
  m.f0 = static_cast<float>(object.material.f0);
  const TriangleMesh world = TransformMesh(object.mesh, object.placement.T_world_object, object.placement.scale);
  MeshShape shape;
  shape.positions = world.positions;
  shape.normals = world.normals;
  shape.triangles = world.triangles;
  shape.material = scene.AddMaterial(m);
  shape.object_id = k;
  scene.meshes.push_back(std::move(shape));
  scene.Build();
  return scene;
}

}  // namespace nerfar::synth

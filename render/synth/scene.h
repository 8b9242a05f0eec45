// Geometry, materials and lights of a synthetic scene, and ray queries on it.
// World frame: metres, right-handed, z up (the table top is z = 0). Radiance is
// linear RGB in image units (an emitter of radiance L seen directly has pixel
// value L). Hot paths are float; ray directions are unit vectors. A Scene is
// built once (Build()) and then read concurrently by any number of threads.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "calib/core/image.h"
#include "calib/core/math.h"

namespace nerfar::synth {

// Albedo image mapped onto world space by a plane projection: the texel of a
// point p is (dot(p - origin, u_axis) / size_u * width, dot(p - origin,
// v_axis) / size_v * height), nearest texel, clamped at the border.
struct PlanarTexture {
  ImageF image;                            // linear RGB albedo in [0, 1]
  Vec3f origin;                            // world point of the image's top-left corner
  Vec3f u_axis{1, 0, 0}, v_axis{0, 1, 0};  // unit world directions of image x and y
  float size_u = 1, size_v = 1;            // world extent of the image along the axes, metres
};

// Lambertian albedo everywhere except `glossy` materials, which use the
// simplified Disney BRDF of DESIGN.md: diffuse (1 - m) a / pi plus a GGX lobe
// (alpha = roughness^2, Smith G, Schlick Fresnel with F0 = mix(f0, a, m)).
struct SurfaceMaterial {
  Vec3f albedo{0.5f, 0.5f, 0.5f};  // linear RGB; multiplied by the texture when there is one
  int texture = -1;                // index into Scene::textures, -1 for none
  bool glossy = false;             // true: Disney/GGX as above, false: Lambertian
  float roughness = 1.0f, metallic = 0.0f, f0 = 0.02f;
  Vec3f emission{0, 0, 0};  // radiance leaving the surface (emitters only)
  bool emits_back = true;   // false: only the side the geometric normal points to emits
};

// Shapes. `material` indexes Scene::materials; `object_id` is -1 for scene
// geometry and >= 0 for an inserted object (masks report it).
struct SphereShape {
  Vec3f center;
  float radius = 0;
  int material = 0, object_id = -1;
};
// Box rotated by yaw about +z around its centre.
struct BoxShape {
  Vec3f center, half_size;
  float yaw_rad = 0;
  int material = 0, object_id = -1;
};
// Closed vertical cylinder: base centre, radius, height (along +z).
struct CylinderShape {
  Vec3f base_center;
  float radius = 0, height = 0;
  int material = 0, object_id = -1;
};
// Rectangle centred at `center` spanning +-half_u along u_axis and +-half_v
// along v_axis (unit, orthogonal); geometric normal u_axis x v_axis.
struct RectangleShape {
  Vec3f center, u_axis{1, 0, 0}, v_axis{0, 1, 0};
  float half_u = 0, half_v = 0;
  int material = 0, object_id = -1;
};
// Triangle mesh in world coordinates; smooth shading when normals are given.
struct MeshShape {
  std::vector<Vec3f> positions, normals;  // normals empty or one per position
  std::vector<std::array<uint32_t, 3>> triangles;
  int material = 0, object_id = -1;
};

// Lights sampled by next-event estimation. Each emitter light also needs its
// geometry in the scene (AddSphereLight etc. add both).
struct SphereLight {
  Vec3f center;
  float radius = 0;
  Vec3f radiance;
};
struct RectangleLight {
  Vec3f center, u_axis, v_axis;  // unit, orthogonal; emits towards u_axis x v_axis
  float half_u = 0, half_v = 0;
  Vec3f radiance;
  bool two_sided = false;
};
struct BoxLight {
  Vec3f center, half_size;
  float yaw_rad = 0;
  Vec3f radiance;  // every face emits outwards
};

// Spherical Gaussian lobe of the environment: mu * exp(lambda (d.p - 1)).
struct EnvLobe {
  Vec3f axis{0, 0, 1};  // unit, world frame
  float sharpness = 1;  // lambda > 0
  Vec3f amplitude;      // mu >= 0, radiance
};

// The distant light: never seen by camera rays, lights the scene from outside
// the NeRF volume. Radiance(d) = sum of lobes + the equirect map's texel at d
// (equirect convention of ../shared/scenes/README.md).
struct Environment {
  std::vector<EnvLobe> lobes;
  ImageF map;  // equirect RGB, empty for none
  bool Present() const { return !lobes.empty() || !map.empty(); }
};

// Equirect convention (README): pixel centre (u, v) in [0,1]^2 <-> direction.
Vec3 EquirectDirection(double u, double v);
void EquirectCoordinates(const Vec3& d, double& u, double& v);

// Everything a ray can meet. Radiance from Environment/lights in image units.
struct Ray {
  Vec3f origin, dir;  // dir unit
  float t_min = 0, t_max = 1e30f;
};

struct Hit {
  float t = 0;
  Vec3f point;
  Vec3f normal;            // shading normal, facing the incoming ray
  Vec3f geometric_normal;  // the shape's own outward normal (not flipped)
  bool front = true;       // the ray met the side the geometric normal points to
  int material = 0, object_id = -1;
};

struct LightSample {
  Vec3f wi;            // unit direction from the shading point to the light
  float distance = 0;  // to the light surface (infinity for the environment)
  Vec3f radiance;      // emitted radiance arriving along -wi (0 if none)
  float pdf = 0;       // solid-angle density of wi; 0: no contribution
};

class Scene {
 public:
  Scene();
  ~Scene();
  Scene(Scene&&) noexcept;
  Scene& operator=(Scene&&) noexcept;

  std::vector<SurfaceMaterial> materials;
  std::vector<PlanarTexture> textures;
  std::vector<SphereShape> spheres;
  std::vector<BoxShape> boxes;
  std::vector<CylinderShape> cylinders;
  std::vector<RectangleShape> rectangles;
  std::vector<MeshShape> meshes;
  std::vector<SphereLight> sphere_lights;
  std::vector<RectangleLight> rectangle_lights;
  std::vector<BoxLight> box_lights;
  Environment environment;

  int AddMaterial(const SurfaceMaterial& material);
  // Emitter geometry (black, non-reflecting) plus its light.
  void AddSphereLight(const SphereLight& light);
  void AddRectangleLight(const RectangleLight& light);
  void AddBoxLight(const BoxLight& light);
  // Removes every shape of an inserted object (object_id), e.g. for renders without it.
  Scene WithoutObject(int object_id) const;
  Scene Copy() const;

  // Builds the acceleration structure and the environment's sampling table;
  // call after the last change and before any query.
  void Build();
  bool built() const { return accel_ != nullptr; }

  bool Intersect(const Ray& ray, Hit& hit) const;
  bool Occluded(const Ray& ray) const;

  // Albedo at a hit (texture applied).
  Vec3f Albedo(const Hit& hit) const;
  // Emitted radiance towards the ray that made the hit (0 for non-emitters).
  Vec3f Emission(const Hit& hit) const;
  // Environment radiance arriving from direction d (travelling along -d).
  Vec3f EnvironmentRadiance(const Vec3f& d) const;

  // Number of NEE light slots: sphere + rectangle + box lights + environment.
  int LightCount() const;
  // Samples light `index` as seen from `point` with two uniform numbers (and a
  // third for box lights). Always consumes the same random numbers.
  LightSample SampleLight(int index, const Vec3f& point, float u1, float u2, float u3) const;

 private:
  struct Accel;
  std::unique_ptr<Accel> accel_;
};

}  // namespace nerfar::synth

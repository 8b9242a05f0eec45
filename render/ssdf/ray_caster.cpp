#include "render/ssdf/ray_caster.h"

#include <embree3/rtcore.h>

#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace nerfar::ssdf_internal {

struct RayCaster::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

namespace {

void ThrowIfDeviceError(RTCDevice device, const char* what) {
  const RTCError error = rtcGetDeviceError(device);
  if (error != RTC_ERROR_NONE)
    throw std::runtime_error(std::string("embree: ") + what + " failed (error code " + std::to_string(error) + ")");
}

}  // namespace

RayCaster::RayCaster(const TriangleMesh& mesh) : impl_(std::make_unique<Impl>()) {
  ValidateMesh(mesh, mesh.source.empty() ? "mesh" : mesh.source).ThrowIfAny();
  impl_->device = rtcNewDevice(nullptr);
  if (impl_->device == nullptr) throw std::runtime_error("embree: cannot create a device");
  impl_->scene = rtcNewScene(impl_->device);
  // Robust traversal: rays through shared edges and vertices do not slip between triangles.
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geometry = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                               3 * sizeof(float), mesh.positions.size()));
  auto* indices = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                 3 * sizeof(uint32_t), mesh.triangles.size()));
  ThrowIfDeviceError(impl_->device, "allocating geometry buffers");
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    vertices[3 * i] = mesh.positions[i].x;
    vertices[3 * i + 1] = mesh.positions[i].y;
    vertices[3 * i + 2] = mesh.positions[i].z;
  }
  std::memcpy(indices, mesh.triangles.data(), mesh.triangles.size() * 3 * sizeof(uint32_t));
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(impl_->scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(impl_->scene);
  ThrowIfDeviceError(impl_->device, "building the BVH");
}

RayCaster::~RayCaster() = default;

bool RayCaster::Occluded(const Vec3f& origin, const Vec3f& dir) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray{};
  ray.org_x = origin.x;
  ray.org_y = origin.y;
  ray.org_z = origin.z;
  ray.dir_x = dir.x;
  ray.dir_y = dir.y;
  ray.dir_z = dir.z;
  ray.tnear = 0.0f;
  ray.tfar = std::numeric_limits<float>::infinity();
  ray.mask = 0xFFFFFFFFu;
  rtcOccluded1(impl_->scene, &context, &ray);
  return ray.tfar < 0.0f;  // set to -inf on a hit
}

void RayCaster::OccludedMany(const Vec3f& origin, const Vec3f* dirs, size_t count, uint8_t* blocked) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;  // one origin, neighbouring directions
  alignas(64) RTCRay16 rays;
  alignas(64) int valid[16];
  for (size_t begin = 0; begin < count; begin += 16) {
    const size_t n = std::min<size_t>(16, count - begin);
    for (size_t k = 0; k < 16; ++k) {
      const Vec3f& d = dirs[begin + std::min(k, n - 1)];
      valid[k] = k < n ? -1 : 0;
      rays.org_x[k] = origin.x;
      rays.org_y[k] = origin.y;
      rays.org_z[k] = origin.z;
      rays.dir_x[k] = d.x;
      rays.dir_y[k] = d.y;
      rays.dir_z[k] = d.z;
      rays.tnear[k] = 0.0f;
      rays.tfar[k] = std::numeric_limits<float>::infinity();
      rays.time[k] = 0.0f;
      rays.mask[k] = 0xFFFFFFFFu;
      rays.id[k] = 0;
      rays.flags[k] = 0;
    }
    rtcOccluded16(valid, impl_->scene, &context, &rays);
    for (size_t k = 0; k < n; ++k) blocked[begin + k] = rays.tfar[k] < 0.0f ? 1 : 0;
  }
}

}  // namespace nerfar::ssdf_internal

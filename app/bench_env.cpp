// Bench stage "env": environment estimation (paper §4.2) on a synthetic NeRF
// grid whose radiance is computed here from a known environment (a Lambertian
// floor and a floating ball, analytic visibility, albedo 0.5): time and the
// relative RMS irradiance error over upper-hemisphere normals, for each preset
// and for the pixels x rays trade (paper figure rays_pixels). End-to-end
// figures on the shared scenes need a trained NeRF (`nerfar env` on it).
#include <algorithm>
#include <cmath>
#include <map>
#include <string>

#include "app/bench.h"
#include "calib/core/log.h"
#include "render/lighting/env_estimate.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"

namespace nerfar {
namespace {

const Vec3 kBall{0.1, -0.05, 0.45};
constexpr double kBallRadius = 0.25;

bool Blocked(const Vec3& x, const Vec3& d) {
  const Vec3 oc = x - kBall;
  const double b = Dot(oc, d), c = Dot(oc, oc) - kBallRadius * kBallRadius, disc = b * b - c;
  if (disc > 0 && -b - std::sqrt(disc) > 1e-9) return true;
  if (d.z < 0 && x.z > 1e-9) {
    const Vec3 hit = x + d * (-x.z / d.z);
    if (std::fabs(hit.x) <= 1 && std::fabs(hit.y) <= 1) return true;
  }
  return false;
}

SgMixture TrueEnvironment() {
  const double el = 35 * kPi / 180, az = 40 * kPi / 180;
  return {Sg{{0, 0, 1}, 1.5, {0.3, 0.35, 0.45}},
          Sg{{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)}, 20.0, {8, 7, 6}}};
}

NerfField SyntheticScene(double voxel) {
  const Aabb box{{-1, -1, -0.2}, {1, 1, 1.0}};
  const SgMixture env = TrueEnvironment();
  const std::vector<Vec3> dirs = FibonacciSphere(4096);
  auto radiance = [&](const Vec3& x, const Vec3& n) {
    Vec3 e;
    for (const Vec3& d : dirs)
      if (Dot(n, d) > 0 && !Blocked(x + n * 1e-6, d)) e += Evaluate(env, d) * Dot(n, d);
    return e * (4 * kPi / dirs.size() * 0.5 / kPi);
  };
  NerfField field = NerfField::Dense(box, voxel, kNerfEmptyDensityRaw, Vec3f{-20, -20, -20});
  std::map<std::pair<int, int>, Vec3> floor;
  for (int k = 0; k < field.res[2]; ++k)
    for (int j = 0; j < field.res[1]; ++j)
      for (int i = 0; i < field.res[0]; ++i) {
        const int32_t slot = field.Slot(i, j, k);
        const Vec3 p = Vec3(field.origin) + Vec3{double(i), double(j), double(k)} * double(field.voxel_m);
        const double ball = Length(p - kBall) - kBallRadius, sd = std::min(p.z, ball);
        field.density[slot] = static_cast<float>(std::clamp(3.0 - 10.0 * sd / voxel, -30.0, 8.0));
        if (std::fabs(sd) > 3 * voxel) continue;
        Vec3 l;
        if (p.z < ball) {
          auto it = floor.find({i, j});
          if (it == floor.end()) it = floor.emplace(std::make_pair(i, j), radiance({p.x, p.y, 0}, {0, 0, 1})).first;
          l = it->second;
        } else {
          const Vec3 n = Normalized(p - kBall);
          l = radiance(kBall + n * kBallRadius, n);
        }
        for (int c = 0; c < 3; ++c) {
          field.color[slot * kNerfColorCoeffs + c * 4] = static_cast<float>(std::log(std::max(l[c], 1e-9)));
          for (int b = 1; b < 4; ++b) field.color[slot * kNerfColorCoeffs + c * 4 + b] = 0;
        }
      }
  field.UpdateOccupancy(1.0f);
  return field;
}

double IrradianceError(const SgMixture& estimate) {
  std::vector<Vec3> a, b;
  for (const Vec3& n : FibonacciSphere(128))
    if (n.z > 0) {
      a.push_back(Irradiance(estimate, n));
      b.push_back(Irradiance(TrueEnvironment(), n));
    }
  return RelativeIrradianceRms(a, b);
}

}  // namespace

std::vector<BenchFigure> BenchEnv(const BenchOptions& options) {
  const NerfField field = SyntheticScene(options.quick ? 0.05 : 0.025);
  std::vector<BenchFigure> figures;
  const std::string scene = "synthetic floor+ball, known env";
  auto run = [&](const std::string& label, EnvEstimateOptions o) {
    o.brisque_max = 100;  // synthetic flat renders are not natural images
    o.min_view_elevation_deg = 5;
    if (options.quick) {
      o.views = 10;
      o.rays_per_point = std::min(o.rays_per_point, 64);
    }
    const double t0 = NowSeconds();
    EnvEstimateReport report;
    const EnvLight env = EstimateEnvironment(field, o, &report);
    const double seconds = NowSeconds() - t0;
    const std::string note = scene + "; " + std::to_string(o.views) + " views x " + std::to_string(o.pixels_per_view) +
                             " px, " + std::to_string(o.rays_per_point) + " rays";
    figures.push_back({"env_" + label + "_s", seconds, "s", note});
    figures.push_back({"env_" + label + "_irradiance_rel_rms", IrradianceError(env.lobes), "", note});
  };
  for (const char* preset : {"fast", "balanced", "accurate"}) {
    if (options.quick && std::string(preset) != "fast") continue;
    run(preset, EnvEstimateOptions::Preset(preset));
  }
  if (!options.quick)
    for (int pixels : {16, 64})
      for (int rays : {64, 256}) {
        EnvEstimateOptions o = EnvEstimateOptions::Preset("balanced");
        o.pixels_per_view = pixels;
        o.rays_per_point = rays;
        run("px" + std::to_string(pixels) + "_rays" + std::to_string(rays), o);
      }
  return figures;
}

}  // namespace nerfar

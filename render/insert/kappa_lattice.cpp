#include "render/insert/kappa_lattice.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace nerfar {

uint32_t NormalCell(const Vec3f& n) {
  const float l1 = std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
  float u = n.x / l1, v = n.y / l1;
  if (n.z < 0) {
    const float pu = (1 - std::abs(v)) * (u >= 0 ? 1.0f : -1.0f), pv = (1 - std::abs(u)) * (v >= 0 ? 1.0f : -1.0f);
    u = pu;
    v = pv;
  }
  const auto cell = [](float t) {
    return static_cast<uint32_t>(std::clamp(static_cast<int>((t + 1) * 0.5f * kNormalCells), 0, kNormalCells - 1));
  };
  return cell(v) * kNormalCells + cell(u);
}

Vec3f CellNormal(uint32_t cell) {
  const float u = ((cell % kNormalCells) + 0.5f) / kNormalCells * 2 - 1;
  const float v = ((cell / kNormalCells) + 0.5f) / kNormalCells * 2 - 1;
  Vec3f n{u, v, 1 - std::abs(u) - std::abs(v)};
  if (n.z < 0) {
    const float x = (1 - std::abs(v)) * (u >= 0 ? 1.0f : -1.0f), y = (1 - std::abs(u)) * (v >= 0 ? 1.0f : -1.0f);
    n.x = x;
    n.y = y;
  }
  return Normalized(n);
}

bool KappaLattice::Find(uint64_t node, float* value) {
  Shard& s = shards_[ShardOf(node)];
  const auto it = s.frozen.find(node);  // read-only during the frame: no lock
  if (it != s.frozen.end()) {
    *value = it->second;
    return true;
  }
  std::lock_guard<std::mutex> lock(s.mutex);
  const auto jt = s.fresh.find(node);
  if (jt == s.fresh.end()) return false;
  *value = jt->second;
  return true;
}

void KappaLattice::Insert(uint64_t node, float value) {
  Shard& s = shards_[ShardOf(node)];
  std::lock_guard<std::mutex> lock(s.mutex);
  s.fresh.emplace(node, value);
}

void KappaLattice::Publish() {
  for (Shard& s : shards_) {
    if (s.fresh.empty()) continue;
    s.frozen.insert(s.fresh.begin(), s.fresh.end());
    s.fresh.clear();
  }
}

size_t KappaLattice::Size() {
  size_t n = 0;
  for (Shard& s : shards_) {
    std::lock_guard<std::mutex> lock(s.mutex);
    n += s.frozen.size() + s.fresh.size();
  }
  return n;
}

void KappaLattice::Clear() {
  for (Shard& s : shards_) {
    std::lock_guard<std::mutex> lock(s.mutex);
    s.frozen.clear();
    s.fresh.clear();
  }
  std::lock_guard<std::mutex> lock(box_mutex_);
  ResetBox();
}

void KappaLattice::ResetBox() {
  const float inf = std::numeric_limits<float>::infinity();
  shadow_min_ = {inf, inf, inf};
  shadow_max_ = {-inf, -inf, -inf};
}

void KappaLattice::GrowShadow(const Vec3f& node) {
  std::lock_guard<std::mutex> lock(box_mutex_);
  shadow_min_ = {std::min(shadow_min_.x, node.x), std::min(shadow_min_.y, node.y), std::min(shadow_min_.z, node.z)};
  shadow_max_ = {std::max(shadow_max_.x, node.x), std::max(shadow_max_.y, node.y), std::max(shadow_max_.z, node.z)};
}

}  // namespace nerfar

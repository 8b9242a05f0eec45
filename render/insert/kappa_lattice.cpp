#include "render/insert/kappa_lattice.h"

#include <algorithm>
#include <bit>
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

bool KappaLattice::FindFresh(uint64_t node, float* value) {
  Shard& s = shards_[ShardOf(node)];
  std::lock_guard<std::mutex> lock(s.mutex);
  const auto it = s.fresh.find(node);
  if (it == s.fresh.end()) return false;
  *value = it->second;
  return true;
}

void KappaLattice::Insert(uint64_t node, float value) {
  if (node == kEmptyKey) return;
  Shard& s = shards_[ShardOf(node)];
  std::lock_guard<std::mutex> lock(s.mutex);
  s.fresh.emplace(node, value);
}

void KappaLattice::FrozenPut(uint64_t key, float value) {
  for (size_t slot = FrozenSlot(key);; slot = (slot + 1) & frozen_mask_) {
    FrozenEntry& e = frozen_[slot];
    if (e.key == key) return;  // a node's value never changes under one key
    if (e.key == kEmptyKey) {
      e = {key, value};
      ++frozen_size_;
      return;
    }
  }
}

void KappaLattice::Publish() {
  size_t fresh = 0;
  for (Shard& s : shards_) fresh += s.fresh.size();
  if (fresh == 0) return;
  // At most half full: grow to the next power of two and re-insert.
  if (2 * (frozen_size_ + fresh) > frozen_.size()) {
    size_t capacity = 1024;
    while (capacity < 4 * (frozen_size_ + fresh)) capacity *= 2;
    std::vector<FrozenEntry> old = std::move(frozen_);
    frozen_.assign(capacity, FrozenEntry{});
    frozen_mask_ = capacity - 1;
    frozen_shift_ = 64 - std::countr_zero(capacity);
    frozen_size_ = 0;
    for (const FrozenEntry& e : old)
      if (e.key != kEmptyKey) FrozenPut(e.key, e.value);
  }
  for (Shard& s : shards_) {
    for (const auto& [key, value] : s.fresh) FrozenPut(key, value);
    s.fresh.clear();
  }
}

size_t KappaLattice::Size() {
  size_t n = frozen_size_;
  for (Shard& s : shards_) {
    std::lock_guard<std::mutex> lock(s.mutex);
    n += s.fresh.size();
  }
  return n;
}

void KappaLattice::Clear() {
  // A small table is kept and emptied (a moving object clears it every
  // frame); a large one is given back.
  if (frozen_.size() > (size_t(1) << 16)) {
    frozen_ = {};
    frozen_mask_ = 0;
    frozen_shift_ = 64;
  } else {
    std::fill(frozen_.begin(), frozen_.end(), FrozenEntry{});
  }
  frozen_size_ = 0;
  for (Shard& s : shards_) {
    std::lock_guard<std::mutex> lock(s.mutex);
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

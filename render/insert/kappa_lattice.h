// Internal to render/insert: κ kept at the nodes of a world lattice, one
// value per node and receiver-normal cell (32×32 octahedral cells), shared
// by the threads of a frame (InsertOptions::kappa_cache_spacing_radii).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "calib/core/math.h"

namespace nerfar {

// Receiver normals in kNormalCells² octahedral cells.
constexpr int kNormalCells = 32;
uint32_t NormalCell(const Vec3f& n);
Vec3f CellNormal(uint32_t cell);  // the cell's central unit normal

// Lattice node (i, j, k) (18 bits each, offset) and normal cell (10 bits).
inline uint64_t LatticeKey(int64_t i, int64_t j, int64_t k, uint32_t cell) {
  constexpr int64_t kOffset = int64_t(1) << 17, kMask = (int64_t(1) << 18) - 1;
  return (uint64_t((i + kOffset) & kMask) << 46) | (uint64_t((j + kOffset) & kMask) << 28) |
         (uint64_t((k + kOffset) & kMask) << 10) | cell;
}
constexpr size_t kKappaCacheMaxNodes = size_t(1) << 22;  // ~4 M nodes (~100 MB): cleared beyond
// Levels below the lattice's own, each of half the spacing above it: four
// take the default spacing (0.15 caster radii) under 0.01 radii, finer than
// a sun's penumbra (λ ~ 1e4: 0.024 radii wide) half a radius from the
// caster.
constexpr size_t kKappaFineLevels = 4;

// The lattice nodes one thread looked up last (direct-mapped by key; value
// -1: empty): neighbouring receivers share most of their 8 nodes, and the
// shared lattice's hash look-up (a cache miss or two) is what dominates κ
// on a frame. Sized for the nodes of one level that a 1280-pixel-wide frame
// of the balanced grid reads (kept across frames while the lattice stays,
// so that the next frame finds most of them); on the heap (too large for a
// thread's static storage). Holds exactly the lattice's values.
struct LatticeMemo {
  static constexpr int kBits = 13;
  static constexpr size_t kMemo = size_t(1) << kBits;
  struct Entry {
    uint64_t key = ~uint64_t(0);
    float value = -1.0f;
  };
  std::vector<Entry> entry = std::vector<Entry>(kMemo);
  void Clear() { std::fill(entry.begin(), entry.end(), Entry{}); }
  static size_t Slot(uint64_t key) { return (key * 0x9E3779B97F4A7C15ull) >> (64 - kBits); }
  Entry& At(uint64_t key) { return entry[Slot(key)]; }
  bool Holds(uint64_t key) const {
    const Entry& e = entry[Slot(key)];
    return e.key == key && !(e.value < 0.0f);
  }
};

// The lattice cells (of one level) one thread read last, with their corner
// values (direct-mapped by the key of the cell's lowest node and normal
// cell; key ~0: empty; value -1: that corner not fetched yet). A cell's
// receivers (a top-level cell spans several κ samples each way at the
// presets' spacing, a finer one fewer) read its corners here instead of
// probing the node memo, and through it the shared lattice, once per
// corner: the lattice's frozen table, larger than the caches, costs a cache
// miss a probe. Holds exactly the lattice's values. On the heap (160 kB).
struct LatticeCellMemo {
  static constexpr int kBits = 12;
  static constexpr size_t kCells = size_t(1) << kBits;
  static constexpr uint64_t kEmpty = ~uint64_t(0);
  std::vector<uint64_t> key = std::vector<uint64_t>(kCells, kEmpty);
  std::vector<std::array<float, 8>> value = std::vector<std::array<float, 8>>(kCells);
  void Clear() { std::fill(key.begin(), key.end(), kEmpty); }
  static size_t Slot(uint64_t key) { return (key * 0x9E3779B97F4A7C15ull) >> (64 - kBits); }
  // The corner values of the cell with key `cell_key` (all −1 when new).
  std::array<float, 8>& Corners(uint64_t cell_key) {
    const size_t slot = Slot(cell_key);
    if (key[slot] != cell_key) {
      key[slot] = cell_key;
      value[slot].fill(-1.0f);
    }
    return value[slot];
  }
};

// The shared lattice. The nodes of earlier frames are a read-only snapshot
// (`frozen`: an open-addressing table of (key, value) pairs, linear probing,
// at most half full, so that a look-up is mostly one cache line; read
// without a lock, nothing writes it during a frame); the nodes computed this
// frame are in per-shard maps under the shard's mutex (`fresh`); Publish()
// (single-threaded, at the start of a frame) moves the fresh nodes into the
// snapshot. Also the world box of the nodes computed with κ < 1 − ε (all
// others hold κ ≥ 1 − ε).
class KappaLattice {
 public:
  KappaLattice() { ResetBox(); }
  bool Find(uint64_t node, float* value) {
    if (!frozen_.empty()) {
      for (size_t slot = FrozenSlot(node);; slot = (slot + 1) & frozen_mask_) {
        const FrozenEntry& e = frozen_[slot];
        if (e.key == node) {
          *value = e.value;
          return true;
        }
        if (e.key == kEmptyKey) break;
      }
    }
    return FindFresh(node, value);
  }
  // Starts loading `node`'s slot of the snapshot into the cache, so that
  // the misses of several nodes looked up next overlap instead of queueing.
  void Prefetch(uint64_t node) const {
    if (!frozen_.empty()) __builtin_prefetch(&frozen_[FrozenSlot(node)]);
  }
  void Insert(uint64_t node, float value);
  void Publish();  // single-threaded, between frames
  size_t Size();
  void Clear();
  void GrowShadow(const Vec3f& node);
  Vec3f shadow_min() const { return shadow_min_; }
  Vec3f shadow_max() const { return shadow_max_; }

 private:
  // No LatticeKey is all ones in practice (node (2^17 − 1)³ in the last
  // normal cell); such a key would just never be kept.
  static constexpr uint64_t kEmptyKey = ~uint64_t(0);
  struct FrozenEntry {
    uint64_t key = kEmptyKey;
    float value = 0.0f;
  };
  size_t FrozenSlot(uint64_t key) const { return size_t((key * 0x9E3779B97F4A7C15ull) >> frozen_shift_); }
  void FrozenPut(uint64_t key, float value);
  bool FindFresh(uint64_t node, float* value);
  std::vector<FrozenEntry> frozen_;  // empty, or a power of two ≥ 2 × frozen_size_
  size_t frozen_mask_ = 0, frozen_size_ = 0;
  int frozen_shift_ = 64;
  static constexpr size_t kShards = 64;
  struct Shard {
    std::mutex mutex;
    std::unordered_map<uint64_t, float> fresh;
  };
  static size_t ShardOf(uint64_t key) { return (key * 0x9E3779B97F4A7C15ull) >> 58; }
  std::array<Shard, kShards> shards_;
  std::mutex box_mutex_;
  Vec3f shadow_min_, shadow_max_;
  void ResetBox();
};

}  // namespace nerfar

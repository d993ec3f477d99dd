#include "tofcam/filters/weingarten_cell_filter.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "filter_internal.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace filters_internal {
namespace {

constexpr std::uint64_t kEmpty = ~std::uint64_t{0};  // no packed key has bit 63 set
constexpr float kMaxCell = static_cast<float>((1 << 20) - 1);
constexpr std::int32_t kUnusable = std::numeric_limits<std::int32_t>::min();

// Open-addressing (linear probing) table from packed cell key to point count, plus each pixel's
// cell and slot. Reused per thread; it only grows.
struct CellTable {
  std::vector<std::uint64_t> keys;
  std::vector<std::uint32_t> counts;     // 4 per slot, see Count
  std::vector<std::int32_t> cx, cy, cz;  // cell indices per pixel; cx = kUnusable if unusable
  std::vector<std::int32_t> slot_of_pixel;
  std::vector<std::uint16_t> flag_of_slot;
  int bits = 0;
};

// floor(v) clamped to ±kMaxCell without a libm call (truncate, then correct negatives).
inline std::int32_t FloorCell(float v) {
  const float c = std::min(std::max(v, -kMaxCell), kMaxCell);
  const std::int32_t i = static_cast<std::int32_t>(c);
  return i - static_cast<std::int32_t>(static_cast<float>(i) > c);
}

// Cell indices of every pixel of the frame (vectorisable: restrict pointers, no branches).
TOFCAM_HOT_LOOP void Cells(std::size_t n, float inv_voxel, const float* __restrict d,
                           const float* __restrict rx, const float* __restrict ry,
                           const float* __restrict rz, const PixelFlags* __restrict pf,
                           std::int32_t* __restrict cx, std::int32_t* __restrict cy,
                           std::int32_t* __restrict cz) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    const bool usable = (d[i] > 0.0f) & (d[i] < kInf) & ((pf[i].bits() & kRejectMask) == 0);
    const float s = usable ? d[i] * inv_voxel : 0.0f;
    // An integer mask instead of `usable ? x : kUnusable`: the AVX2 clone otherwise keeps a branch.
    const std::int32_t mask = -static_cast<std::int32_t>(usable);
    cx[i] = (FloorCell(s * rx[i]) & mask) | (kUnusable & ~mask);
    cy[i] = FloorCell(s * ry[i]);
    cz[i] = FloorCell(s * rz[i]);
  }
}

std::uint64_t Pack(std::int32_t x, std::int32_t y, std::int32_t z) {
  constexpr std::int64_t kBias = 1 << 20;
  return static_cast<std::uint64_t>(x + kBias) | (static_cast<std::uint64_t>(y + kBias) << 21) |
         (static_cast<std::uint64_t>(z + kBias) << 42);
}

std::size_t Hash(std::uint64_t key, int bits) {
  return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ull) >> (64 - bits));
}

void Reset(CellTable& t, std::size_t min_capacity) {
  int bits = 10;
  while ((std::size_t{1} << bits) < min_capacity) ++bits;
  if (bits > t.bits) t.bits = bits;
  const std::size_t cap = std::size_t{1} << t.bits;
  t.keys.assign(cap, kEmpty);
  t.counts.assign(cap, 0);
}

// Counts the points per cell; false when the table passed half load (caller grows it).
bool Count(CellTable& t, std::size_t n) {
  const std::size_t mask = (std::size_t{1} << t.bits) - 1;
  const std::size_t limit = std::size_t{1} << (t.bits - 1);
  std::size_t used = 0;
  const std::int32_t* cx = t.cx.data();
  const std::int32_t* cy = t.cy.data();
  const std::int32_t* cz = t.cz.data();
  std::int32_t* slot_of = t.slot_of_pixel.data();
  std::uint64_t* keys = t.keys.data();
  std::uint32_t* counts = t.counts.data();
  // No "same cell as the left neighbour" shortcut: on noisy data that branch mispredicts often,
  // while the probe below almost always hits on its first compare (a well-predicted branch).
  for (std::size_t p = 0; p < n; ++p) {
    if (cx[p] == kUnusable) {
      slot_of[p] = -1;
      continue;
    }
    const std::uint64_t key = Pack(cx[p], cy[p], cz[p]);
    std::size_t i = Hash(key, t.bits);
    while (keys[i] != key && keys[i] != kEmpty) i = (i + 1) & mask;
    if (keys[i] == kEmpty) {
      keys[i] = key;
      if (++used > limit) return false;
    }
    ++counts[i];
    slot_of[p] = static_cast<std::int32_t>(i);
  }
  return true;
}

}  // namespace

void WeingartenInto(const MetricFrame& frame, const Image<PixelFlags>& prior, const RayTable& rays,
                    const WeingartenCellOptions& o, Image<PixelFlags>& out) {
  const int w = frame.width(), h = frame.height();
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  thread_local CellTable t;
  for (auto* v : {&t.cx, &t.cy, &t.cz, &t.slot_of_pixel}) v->resize(n);
  Cells(n, static_cast<float>(1.0 / o.voxel_size_m), frame.radial_distance_m.data(), rays.x.data(),
        rays.y.data(), rays.z.data(), PriorOrZeros(prior, n), t.cx.data(), t.cy.data(),
        t.cz.data());

  // The table keeps the size the last frames needed (small tables stay in L1: distinct cells are
  // far fewer than points), doubles whenever it passes half load, and never needs more than 2n
  // slots.
  int max_bits = 10;
  while ((std::size_t{1} << max_bits) < 2 * n) ++max_bits;
  t.bits = std::min(t.bits, max_bits);
  Reset(t, 1024);
  while (!Count(t, n)) {
    t.bits += 1;
    Reset(t, 0);
  }

  // Per slot, the flag a point in it gets (slot -1, unusable, maps to entry 0 = no flag); the
  // per-pixel loop is then a branch-free table lookup.
  const std::uint32_t min_points = static_cast<std::uint32_t>(o.min_points);
  const std::uint16_t bit = static_cast<std::uint16_t>(Flag::kSparseCell);
  const std::size_t cap = std::size_t{1} << t.bits;
  t.flag_of_slot.resize(cap + 1);
  t.flag_of_slot[0] = 0;
  for (std::size_t i = 0; i < cap; ++i) {
    t.flag_of_slot[i + 1] = static_cast<std::uint16_t>(t.counts[i] < min_points ? bit : 0);
  }
  const std::uint16_t* table = t.flag_of_slot.data() + 1;
  const std::int32_t* slot = t.slot_of_pixel.data();
  PixelFlags* f = out.data();
  for (std::size_t i = 0; i < n; ++i) f[i] |= PixelFlags(table[slot[i]]);
}

}  // namespace filters_internal

void WeingartenCellOptions::Validate() const {
  if (!(voxel_size_m >= 0.001 && voxel_size_m <= 100.0)) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "weingarten.voxel_size_m = " + std::to_string(voxel_size_m) + " is outside [0.001, 100] m");
  }
  if (min_points < 1 || min_points > 1'000'000) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "weingarten.min_points = " + std::to_string(min_points) + " is outside [1, 1000000]");
  }
}

Image<PixelFlags> WeingartenCellFilter(const MetricFrame& frame, const RayTable& rays,
                                       const WeingartenCellOptions& options) {
  options.Validate();
  filters_internal::CheckFrame(frame, "weingarten cell filter");
  filters_internal::CheckRays(frame, rays, "weingarten cell filter");
  Image<PixelFlags> out(frame.width(), frame.height());
  filters_internal::WeingartenInto(frame, frame.flags, rays, options, out);
  return out;
}

}  // namespace tofcam

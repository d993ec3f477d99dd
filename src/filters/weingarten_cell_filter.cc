#include "tofcam/filters/weingarten_cell_filter.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "../core/avx512_forms.h"
#include "filter_internal.h"
#include "simd.h"
#include "tofcam/core/error.h"

#if defined(TOFCAM_AVX512_FORMS)
#include <immintrin.h>
#endif

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

// --- Dense grid over the bounding box of the occupied cells -----------------------------------
//
// The usual case: the frame's points span a box of a few hundred thousand cells (SR-2 pavilion,
// 0.1 m: 53 x 44 x 73), so each point's cell gets a linear index into a flat count array and no
// hashing or probing is needed. The array is all zeros between calls: the cells a frame touches
// are listed while counting and zeroed afterwards, so no clearing of the whole box per frame.

struct Box {
  std::int32_t x0 = 0, y0 = 0, z0 = 0, x1 = -1, y1 = -1, z1 = -1;  // inclusive; empty if x1 < x0
};

// Bounding box of the usable points' cells (vectorisable min / max reductions).
TOFCAM_HOT_LOOP void Bounds(std::size_t n, const std::int32_t* __restrict cx,
                            const std::int32_t* __restrict cy, const std::int32_t* __restrict cz,
                            Box& box) {
  constexpr std::int32_t kHi = std::numeric_limits<std::int32_t>::max();
  std::int32_t x0 = kHi, y0 = kHi, z0 = kHi, x1 = kUnusable, y1 = kUnusable, z1 = kUnusable;
  for (std::size_t i = 0; i < n; ++i) {
    // Integer masks instead of selects: GCC keeps a branch for `usable ? x : k` here.
    const std::int32_t m = -static_cast<std::int32_t>(cx[i] != kUnusable);
    x0 = std::min(x0, (cx[i] & m) | (kHi & ~m));
    y0 = std::min(y0, (cy[i] & m) | (kHi & ~m));
    z0 = std::min(z0, (cz[i] & m) | (kHi & ~m));
    x1 = std::max(x1, cx[i]);  // kUnusable is the smallest int32
    y1 = std::max(y1, (cy[i] & m) | (kUnusable & ~m));
    z1 = std::max(z1, (cz[i] & m) | (kUnusable & ~m));
  }
  box = {x0, y0, z0, x1, y1, z1};
}

// Unusable points get one of the kDummies cells past the box, by position (DummyOf): runs of
// them then increment eight counters in turn instead of one (a chain of store-to-load latency).
constexpr std::int32_t kDummies = 8;
inline std::int32_t DummyOf(std::int32_t dummy, std::size_t i) {
  return dummy + static_cast<std::int32_t>(i & (kDummies - 1));
}

// Linear cell index in the box, or a dummy cell (DummyOf, past the box) for unusable points.
TOFCAM_HOT_LOOP void LinearIndex(std::size_t n, const Box& box, std::int32_t dx, std::int32_t dy,
                                 std::int32_t dummy, const std::int32_t* __restrict cx,
                                 const std::int32_t* __restrict cy,
                                 const std::int32_t* __restrict cz, std::int32_t* __restrict idx) {
  const std::int32_t x0 = box.x0, y0 = box.y0, z0 = box.z0;
  for (std::size_t i = 0; i < n; ++i) {
    // Unusable points (cx = kUnusable, cy = cz = 0) are moved into the box before the
    // arithmetic, so nothing overflows; their index is replaced by the dummy anyway.
    const std::int32_t m = -static_cast<std::int32_t>(cx[i] != kUnusable);
    const std::int32_t x = (cx[i] & m) | (x0 & ~m), y = (cy[i] & m) | (y0 & ~m);
    const std::int32_t z = (cz[i] & m) | (z0 & ~m);
    const std::int32_t linear = ((z - z0) * dy + (y - y0)) * dx + (x - x0);
    idx[i] = (linear & m) | (DummyOf(dummy, i) & ~m);
  }
}

// The count arrays are never cleared per frame: each entry holds a frame stamp in its top 8 bits
// and the count in the low 24, and an entry with another frame's stamp counts as 0. (Clearing
// the touched cells cost a list whose length depended on every count's load, serialising the
// counting loop; clearing every pixel's cell cost as much again in stores.) A stamp is reused
// after 255 frames, when the array is cleared once. Counts stay below 2^24 because the dense
// path takes only frames with fewer usable points (and fewer than 8 * 2^24 pixels).
constexpr int kCountBits = 24;
constexpr std::uint32_t kCountMask = (std::uint32_t{1} << kCountBits) - 1;

// counts[c] + 1 under `stamp`: the entry's count if it carries the stamp, else a first point.
[[gnu::always_inline]] inline std::uint32_t Incremented(std::uint32_t v, std::uint32_t stamp) {
  return (v ^ stamp) <= kCountMask ? v + 1 : stamp + 1;
}

// Counts the points per cell. Eight interleaved streams (eighths of the image): runs of
// neighbouring pixels in one cell increment the same counter, a store-to-load chain of several
// cycles per point; eight independent chains overlap. The streams start q pixels apart with
// q = 1 (mod 8), so in one step they hit eight different dummy cells (DummyOf).
constexpr std::size_t kStreams = 8;

void CountDense(std::size_t n, const std::int32_t* __restrict idx, std::uint32_t stamp,
                std::uint32_t* __restrict counts) {
  auto add = [&](std::size_t p) {
    const std::int32_t c = idx[p];
    counts[c] = Incremented(counts[c], stamp);
  };
  const std::size_t q = n / kStreams + ((kStreams + 1 - n / kStreams % kStreams) % kStreams);
  // Stream k covers [k q, (k + 1) q), the last one [7 q, n). Steps in which all eight streams
  // still have a pixel, then each stream's rest.
  const std::size_t steps = n > (kStreams - 1) * q ? std::min(q, n - (kStreams - 1) * q) : 0;
  for (std::size_t i = 0; i < steps; ++i) {
    for (std::size_t k = 0; k < kStreams; ++k) add(i + k * q);
  }
  for (std::size_t k = 0; k < kStreams; ++k) {
    const std::size_t end = k + 1 < kStreams ? std::min((k + 1) * q, n) : n;
    for (std::size_t p = k * q + steps; p < end; ++p) add(p);
  }
}

// kSparseCell where the point's cell holds fewer than min_points points (dummy cells, from
// `dummy` on: unusable, never flagged). Every usable point's cell carries this frame's stamp, so
// its count is counts[c] - stamp and "fewer than min_points" is counts[c] < stamp + min_points.
// On AVX-512 CPUs FlagDense16 does the work and this loop only its last n mod 16 pixels (and the
// whole frame under the tests' portable switch).
TOFCAM_HOT_LOOP_WIDE void FlagDense(std::size_t n, const std::int32_t* __restrict idx,
                                    std::int32_t dummy, const std::uint32_t* __restrict counts,
                                    std::uint32_t limit, PixelFlags* __restrict f) {
  const std::uint16_t bit = static_cast<std::uint16_t>(Flag::kSparseCell);
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t c = idx[i];
    const unsigned sparse =
        static_cast<unsigned>(c < dummy) & static_cast<unsigned>(counts[c] < limit);
    f[i] |= PixelFlags(static_cast<std::uint16_t>(sparse * bit));
  }
}

#if defined(TOFCAM_AVX512_FORMS)
// FlagDense for AVX-512 CPUs, sixteen pixels at a time with a hardware gather of the counts. GCC
// compiles FlagDense's table reads (in any clone) as scalar loads and inserts, about two cycles
// a pixel on Zen 4; the gather is faster there (filters_bench, SR-2: Weingarten 38-40 -> 35-38
// us). The same flags: a pixel is flagged where its cell is real (below `dummy`) and its stamped
// count below `limit`, compared unsigned as in FlagDense. Dummy cells are not read (masked
// gather). The rest of the row (n mod 16) goes to FlagDense.
TOFCAM_AVX512_TARGET void FlagDense16(std::size_t n, const std::int32_t* __restrict idx,
                                      std::int32_t dummy, const std::uint32_t* __restrict counts,
                                      std::uint32_t limit, PixelFlags* __restrict f) {
  const __m512i vdummy = _mm512_set1_epi32(dummy);
  const __m512i vlimit = _mm512_set1_epi32(static_cast<int>(limit));
  const __m256i bit = _mm256_set1_epi16(static_cast<short>(Flag::kSparseCell));
  std::size_t i = 0;
  for (; i + 16 <= n; i += 16) {
    const __m512i c = _mm512_loadu_si512(idx + i);
    const __mmask16 real = _mm512_cmplt_epi32_mask(c, vdummy);
    // Lanes of dummy cells keep `limit`, which is not below it.
    const __m512i k = _mm512_mask_i32gather_epi32(vlimit, real, c, counts, 4);
    const __mmask16 sparse = _mm512_mask_cmplt_epu32_mask(real, k, vlimit);
    auto* fi = reinterpret_cast<__m256i*>(f + i);
    _mm256_storeu_si256(
        fi, _mm256_or_si256(_mm256_loadu_si256(fi), _mm256_maskz_mov_epi16(sparse, bit)));
  }
  FlagDense(n - i, idx + i, dummy, counts, limit, f + i);
}
#endif

// --- One-pass dense path ----------------------------------------------------------------------
//
// The cell box can be bounded before computing any cell: with s = fl(d / voxel) in [s_lo, s_hi]
// (usable distances) and a ray component r in [r_lo, r_hi], fl(s r) is monotone in each factor
// (correctly rounded products of non-negative s), so its extremes are at the four corners, and
// FloorCell is monotone too. The linear index then comes straight from the distance and the
// rays in one vectorised pass, without storing three cell coordinates per pixel.

struct Range {
  float lo, hi;
  std::size_t count = 0;  // usable distances (DistanceRange)
};

// Usable distances' range (usable: finite, > 0, no reject bit, as in Cells). Written with
// vector extensions: GCC does not vectorise float min / max reductions by itself (NaN and
// signed-zero rules); min and max are exact, so the lane order does not matter.
TOFCAM_HOT_LOOP void DistanceRange(std::size_t n, const float* __restrict d,
                                   const PixelFlags* __restrict pf, Range& out) {
  using namespace simd;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  // Two independent accumulator sets (see RayRange).
  F8 lo[2], hi[2];
  I8 count[2] = {};
  for (int k = 0; k < 2; ++k) {
    lo[k] = kInf - F8{};
    hi[k] = -kInf - F8{};
  }
  std::size_t i = 0;
  for (; i + 16 <= n; i += 16) {
    for (int k = 0; k < 2; ++k) {
      const F8 x = LoadF8(d + i + 8 * k);
      const I8 usable = (x > 0.0f) & (x < kInf) & ((LoadFlags8(pf + i + 8 * k) & kRejectMask) == 0);
      lo[k] = (usable & (x < lo[k])) ? x : lo[k];
      hi[k] = (usable & (x > hi[k])) ? x : hi[k];
      count[k] -= usable;  // masks are -1
    }
  }
  float l = kInf, h = -kInf;
  std::size_t c = 0;
  for (int k = 0; k < 2; ++k) {
    for (int j = 0; j < 8; ++j) {
      l = std::min(l, lo[k][j]);
      h = std::max(h, hi[k][j]);
      c += static_cast<std::size_t>(count[k][j]);
    }
  }
  for (; i < n; ++i) {
    const bool usable = (d[i] > 0.0f) & (d[i] < kInf) & ((pf[i].bits() & kRejectMask) == 0);
    if (usable) {
      l = std::min(l, d[i]);
      h = std::max(h, d[i]);
      ++c;
    }
  }
  out = {l, h, c};
}

// Range of one ray component (finite by construction of a ray table). Four independent
// accumulator pairs: one pair would chain every min / max on the previous one's latency.
TOFCAM_HOT_LOOP void RayRange(std::size_t n, const float* __restrict r, Range& out) {
  using namespace simd;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  F8 lo[4], hi[4];
  for (int k = 0; k < 4; ++k) {
    lo[k] = kInf - F8{};
    hi[k] = -kInf - F8{};
  }
  std::size_t i = 0;
  for (; i + 32 <= n; i += 32) {
    for (int k = 0; k < 4; ++k) {
      const F8 x = LoadF8(r + i + 8 * k);
      lo[k] = x < lo[k] ? x : lo[k];
      hi[k] = x > hi[k] ? x : hi[k];
    }
  }
  float l = kInf, h = -kInf;
  for (int k = 0; k < 4; ++k) {
    for (int j = 0; j < 8; ++j) {
      l = std::min(l, lo[k][j]);
      h = std::max(h, hi[k][j]);
    }
  }
  for (; i < n; ++i) {
    l = std::min(l, r[i]);
    h = std::max(h, r[i]);
  }
  out = {l, h, 0};
}

// Cell range of fl(s r) over the rectangle of s and r.
void CellRange(float inv_voxel, Range d, Range r, std::int32_t& lo, std::int32_t& hi) {
  const float s_lo = d.lo * inv_voxel, s_hi = d.hi * inv_voxel;
  const std::int32_t c[4] = {FloorCell(s_lo * r.lo), FloorCell(s_lo * r.hi), FloorCell(s_hi * r.lo),
                             FloorCell(s_hi * r.hi)};
  lo = std::min(std::min(c[0], c[1]), std::min(c[2], c[3]));
  hi = std::max(std::max(c[0], c[1]), std::max(c[2], c[3]));
}

// FloorCell without the clamp, for values known to lie inside (-kMaxCell, kMaxCell), where the
// clamp does nothing (the box check guarantees it).
inline std::int32_t FloorInBox(float v) {
  const std::int32_t i = static_cast<std::int32_t>(v);
  return i - static_cast<std::int32_t>(static_cast<float>(i) > v);
}

// Linear index of each usable point's cell in `box` (the same cells as Cells computes), or
// `dummy` for unusable points. The box lies strictly inside +-kMaxCell.
TOFCAM_HOT_LOOP void DirectIndex(std::size_t n, float inv_voxel, const Box& box, std::int32_t dx,
                                 std::int32_t dy, std::int32_t dummy, const float* __restrict d,
                                 const float* __restrict rx, const float* __restrict ry,
                                 const float* __restrict rz, const PixelFlags* __restrict pf,
                                 std::int32_t* __restrict idx) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const std::int32_t x0 = box.x0, y0 = box.y0, z0 = box.z0;
  for (std::size_t i = 0; i < n; ++i) {
    const bool usable = (d[i] > 0.0f) & (d[i] < kInf) & ((pf[i].bits() & kRejectMask) == 0);
    const float s = usable ? d[i] * inv_voxel : 0.0f;
    const std::int32_t m = -static_cast<std::int32_t>(usable);
    // Unusable points are moved to the box corner first, so nothing overflows.
    const std::int32_t x = (FloorInBox(s * rx[i]) & m) | (x0 & ~m);
    const std::int32_t y = (FloorInBox(s * ry[i]) & m) | (y0 & ~m);
    const std::int32_t z = (FloorInBox(s * rz[i]) & m) | (z0 & ~m);
    const std::int32_t linear = ((z - z0) * dy + (y - y0)) * dx + (x - x0);
    idx[i] = (linear & m) | (DummyOf(dummy, i) & ~m);
  }
}

// DirectIndex for boxes of fewer than 2^24 cells: the same cells with the index computed in
// float, exact there (every intermediate is an integer below 2^24), and floor as one rounding
// instruction instead of integer multiplies (slow in AVX2) and conversions back and forth. With an
// AVX-512 clone (FMA there changes nothing: the products and sums are exact integers), as for
// FlagDense (measured before FlagDense16 took over on AVX-512 CPUs): filters_bench, four
// interleaved runs, SR-2 38.6-40.6 against 40.4-42.4 us.
TOFCAM_HOT_LOOP_WIDE void DirectIndexFloat(std::size_t n, float inv_voxel, const Box& box, float dx,
                                           float dy, std::int32_t dummy, const float* __restrict d,
                                           const float* __restrict rx, const float* __restrict ry,
                                           const float* __restrict rz,
                                           const PixelFlags* __restrict pf,
                                           std::int32_t* __restrict idx) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const float x0 = static_cast<float>(box.x0), y0 = static_cast<float>(box.y0);
  const float z0 = static_cast<float>(box.z0);
  for (std::size_t i = 0; i < n; ++i) {
    const bool usable = (d[i] > 0.0f) & (d[i] < kInf) & ((pf[i].bits() & kRejectMask) == 0);
    // The rays are read whatever `usable` says: read inside the selects below, GCC makes them
    // masked loads (vmaskmovps), several times slower than plain ones on AMD Zen.
    const float ux = rx[i], uy = ry[i], uz = rz[i];
    // Unusable points are moved to the box corner first, so the conversion stays in range.
    const float s = usable ? d[i] * inv_voxel : 0.0f;
    const float x = usable ? __builtin_floorf(s * ux) - x0 : 0.0f;
    const float y = usable ? __builtin_floorf(s * uy) - y0 : 0.0f;
    const float z = usable ? __builtin_floorf(s * uz) - z0 : 0.0f;
    const std::int32_t linear = static_cast<std::int32_t>((z * dy + y) * dx + x);
    const std::int32_t m = -static_cast<std::int32_t>(usable);
    idx[i] = (linear & m) | (DummyOf(dummy, i) & ~m);
  }
}

struct DenseScratch {
  std::vector<std::int32_t> idx;
  std::vector<std::uint32_t> counts;  // stamped counts (CountDense), or 0
  std::uint32_t frame_stamp = 0;      // the last frame's stamp, 1..255 (0: none yet)
};

// The sparse case (most pixels unusable, e.g. after the other filters of the full set): runs of
// eight pixels are tested at once and skipped when none is usable; the rest count and flag one
// by one.
// True when the eight indices at `idx` are all dummy cells (>= dummy).
inline bool AllDummy(const std::int32_t* idx, std::int32_t dummy) {
  std::int32_t lowest = idx[0];
  for (int j = 1; j < 8; ++j) lowest = std::min(lowest, idx[j]);
  return lowest >= dummy;
}

void CountSparse(std::size_t n, const std::int32_t* __restrict idx, std::int32_t dummy,
                 std::uint32_t stamp, std::uint32_t* __restrict counts) {
  // Branch-free inside a block, as in CountDense: usable and unusable pixels interleave at random
  // after the other filters, so "skip the unusable one" would mispredict about every other pixel.
  auto add = [&](std::size_t p) {
    const std::int32_t c = idx[p];
    counts[c] = Incremented(counts[c], stamp);
  };
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    if (AllDummy(idx + i, dummy)) continue;
    for (std::size_t j = i; j < i + 8; ++j) add(j);
  }
  for (; i < n; ++i) add(i);
}

// FlagDense for the sparse case (`limit` = stamp + min_points as there).
void FlagSparse(std::size_t n, const std::int32_t* __restrict idx, std::int32_t dummy,
                const std::uint32_t* __restrict counts, std::uint32_t limit,
                PixelFlags* __restrict f) {
  const std::uint16_t bit = static_cast<std::uint16_t>(Flag::kSparseCell);
  auto flag = [&](std::size_t p) {
    const std::int32_t c = idx[p];
    const unsigned sparse =
        static_cast<unsigned>(c < dummy) & static_cast<unsigned>(counts[c] < limit);
    f[p] |= PixelFlags(static_cast<std::uint16_t>(sparse * bit));
  };
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    if (AllDummy(idx + i, dummy)) continue;
    for (std::size_t j = i; j < i + 8; ++j) flag(j);
  }
  for (; i < n; ++i) flag(i);
}

// Counts in the dense array and flags; `idx` holds each pixel's linear index or a dummy cell
// (DummyOf(cells, i)).
// With `usable` below an eighth of the pixels (typically the full filter set, where earlier
// filters rejected most of the frame) runs of unusable pixels are skipped eight at a time;
// otherwise every pixel is counted, the unusable ones in dummy cells (vectorised flags).
void CountAndFlag(std::size_t n, std::size_t usable, std::int32_t cells, std::uint32_t min_points,
                  DenseScratch& d, PixelFlags* out) {
  if (d.counts.size() < static_cast<std::size_t>(cells) + kDummies) {
    d.counts.assign(static_cast<std::size_t>(cells) + kDummies, 0);
    d.frame_stamp = 0;
  }
  if (++d.frame_stamp > 255) {
    std::fill(d.counts.begin(), d.counts.end(), 0u);
    d.frame_stamp = 1;
  }
  const std::uint32_t stamp = d.frame_stamp << kCountBits;
  const std::uint32_t limit = stamp + min_points;  // min_points <= 1e6 < 2^24: no overflow
  if (8 * usable < n) {
    CountSparse(n, d.idx.data(), cells, stamp, d.counts.data());
    FlagSparse(n, d.idx.data(), cells, d.counts.data(), limit, out);
  } else {
    CountDense(n, d.idx.data(), stamp, d.counts.data());
#if defined(TOFCAM_AVX512_FORMS)
    if (internal::UseAvx512Forms()) {
      FlagDense16(n, d.idx.data(), cells, d.counts.data(), limit, out);
      return;
    }
#endif
    FlagDense(n, d.idx.data(), cells, d.counts.data(), limit, out);
  }
}

// Largest box (cells) the dense path allocates for n points.
std::int64_t DenseLimit(std::size_t n) {
  return std::max<std::int64_t>(std::int64_t{1} << 20, 4 * static_cast<std::int64_t>(n));
}

bool BoxFits(const Box& box, std::int64_t limit, std::int64_t& cells) {
  const std::int64_t dx = std::int64_t{box.x1} - box.x0 + 1;
  const std::int64_t dy = std::int64_t{box.y1} - box.y0 + 1;
  const std::int64_t dz = std::int64_t{box.z1} - box.z0 + 1;
  if (!(dx <= limit && dy <= limit && dz <= limit && dx * dy <= limit && dx * dy * dz <= limit)) {
    return false;
  }
  cells = dx * dy * dz;
  return true;
}

}  // namespace

RayBounds MakeRayBounds(const RayTable& rays) {
  const std::size_t n = rays.x.size();
  Range rx{}, ry{}, rz{};
  RayRange(n, rays.x.data(), rx);
  RayRange(n, rays.y.data(), ry);
  RayRange(n, rays.z.data(), rz);
  return {rx.lo, rx.hi, ry.lo, ry.hi, rz.lo, rz.hi};
}

void WeingartenInto(const MetricFrame& frame, const Image<PixelFlags>& prior, const RayTable& rays,
                    const WeingartenCellOptions& o, Image<PixelFlags>& out) {
  WeingartenInto(frame, prior, rays, MakeRayBounds(rays), o, out);
}

void WeingartenInto(const MetricFrame& frame, const Image<PixelFlags>& prior, const RayTable& rays,
                    const RayBounds& bounds, const WeingartenCellOptions& o,
                    Image<PixelFlags>& out) {
  const int w = frame.width(), h = frame.height();
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  const float inv_voxel = static_cast<float>(1.0 / o.voxel_size_m);
  const std::uint32_t min_points = static_cast<std::uint32_t>(o.min_points);
  const float* d = frame.radial_distance_m.data();
  const PixelFlags* pf = PriorOrZeros(prior, n);
  const std::int64_t limit = DenseLimit(n);
  thread_local DenseScratch dense;

  // The box from the distance range and the ray bounds (no per-pixel cells stored).
  Range dr{};
  DistanceRange(n, d, pf, dr);
  if (!(dr.lo <= dr.hi)) return;  // no usable point
  const Range rx{bounds.x_lo, bounds.x_hi}, ry{bounds.y_lo, bounds.y_hi};
  const Range rz{bounds.z_lo, bounds.z_hi};
  Box box;
  CellRange(inv_voxel, dr, rx, box.x0, box.x1);
  CellRange(inv_voxel, dr, ry, box.y0, box.y1);
  CellRange(inv_voxel, dr, rz, box.z0, box.z1);
  std::int64_t cells = 0;
  constexpr std::int32_t kInside = (1 << 20) - 2;  // |cell| below kMaxCell: FloorCell's clamp idle
  const bool inside = box.x0 >= -kInside && box.y0 >= -kInside && box.z0 >= -kInside &&
                      box.x1 <= kInside && box.y1 <= kInside && box.z1 <= kInside;
  // The stamped counts need fewer than 2^24 points per cell: a cell holds at most the usable
  // points, a dummy cell an eighth of the pixels (+1). Beyond that the hash table counts.
  const bool dense_ok = dr.count <= kCountMask && n / kDummies < kCountMask;
  if (dense_ok && inside && BoxFits(box, limit, cells)) {
    dense.idx.resize(n);
    if (cells < (std::int64_t{1} << 24)) {
      DirectIndexFloat(n, inv_voxel, box, static_cast<float>(box.x1 - box.x0 + 1),
                       static_cast<float>(box.y1 - box.y0 + 1), static_cast<std::int32_t>(cells), d,
                       rays.x.data(), rays.y.data(), rays.z.data(), pf, dense.idx.data());
    } else {
      DirectIndex(n, inv_voxel, box, box.x1 - box.x0 + 1, box.y1 - box.y0 + 1,
                  static_cast<std::int32_t>(cells), d, rays.x.data(), rays.y.data(), rays.z.data(),
                  pf, dense.idx.data());
    }
    CountAndFlag(n, dr.count, static_cast<std::int32_t>(cells), min_points, dense, out.data());
    return;
  }

  // The bound was too loose (or the points really are spread out): cells per pixel, the exact
  // box of the occupied cells, and the dense array if that box is small enough.
  thread_local CellTable t;
  for (auto* v : {&t.cx, &t.cy, &t.cz}) v->resize(n);
  Cells(n, inv_voxel, d, rays.x.data(), rays.y.data(), rays.z.data(), pf, t.cx.data(), t.cy.data(),
        t.cz.data());
  Bounds(n, t.cx.data(), t.cy.data(), t.cz.data(), box);
  if (dense_ok && BoxFits(box, limit, cells)) {
    dense.idx.resize(n);
    LinearIndex(n, box, box.x1 - box.x0 + 1, box.y1 - box.y0 + 1, static_cast<std::int32_t>(cells),
                t.cx.data(), t.cy.data(), t.cz.data(), dense.idx.data());
    CountAndFlag(n, dr.count, static_cast<std::int32_t>(cells), min_points, dense, out.data());
    return;
  }

  // Scattered points over a huge box: count in the hash table. It keeps the size the last
  // frames needed (small tables stay in L1: distinct cells are far fewer than points), doubles
  // whenever it passes half load, and never needs more than 2n slots.
  for (auto* v : {&t.slot_of_pixel}) v->resize(n);
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

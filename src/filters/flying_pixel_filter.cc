#include "tofcam/filters/flying_pixel_filter.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

#include "../core/avx512_forms.h"
#include "filter_internal.h"
#include "simd.h"
#include "tofcam/core/error.h"

// The AVX-512 form (column strips, FlyingPixelStrips16): see src/core/avx512_forms.h.
#if defined(TOFCAM_AVX512_FORMS)
#include <immintrin.h>
#endif

namespace tofcam {
namespace filters_internal {
namespace {

// The portable form (AVX-512 CPUs run FlyingPixelStrips16 instead, below): the test is split
// by cost. The distance conditions need only the 3x3 minimum and maximum of the distance
// (separable: a horizontal 3-min / 3-max per row, then three rows), evaluated for
// every pixel in vectorised row loops. The amplitude contrast needs the window's count, sum and
// sum of squares; it is evaluated only where the distance conditions hold (a few per cent of the
// pixels: depth edges), in the same order of float operations as a full evaluation (horizontal
// sums per row, then rows up + mid + down), so the result is bit for bit that of the rule.
//
// Rows are prepared once into a ring of four padded rows: weight (1 usable, 0 not) and amplitude
// (0 if unusable), with their horizontal 3-min / 3-max of the distance (unusable pixels never
// win). A neutral row (weight 0, amplitude 0, distances that never win) stands above the first
// and below the last row. Reused per thread so a stable frame size allocates nothing.
struct Prepared {
  float* w;
  float* a;
};

// Ring slots: four rows (the row above, the row or two rows decided, the row below) and a
// neutral slot.
constexpr int kRingSlots = 4;
constexpr int kNeutral = kRingSlots;
constexpr int kSlots = kRingSlots + 1;

struct Scratch {
  std::vector<float> prepared;  // kSlots x 2 streams x (w + 2)
  std::vector<float> minmax;    // kSlots x 2 streams (3-min, 3-max) x w
  std::vector<float> sums;      // kSlots x 3 streams (count, Σa, Σa²) x w, when a row needs them
  std::vector<std::uint8_t> candidate;  // one row, padded to a multiple of 8
  std::vector<PixelFlags> echo_sink;    // one row
};

// The loops live in functions with __restrict parameters: with many pointers GCC otherwise
// gives up on the run-time alias checks and does not vectorise. Output pointers point at the
// padded row's first pixel (index 0 = column 0; index -1 and w are the pad).

// Horizontal 3-sums of one prepared row: count, Σa, Σa² (cw, ca padded).
TOFCAM_HOT_LOOP void HorizontalSums(int w, const float* __restrict cw, const float* __restrict ca,
                                    float* __restrict n, float* __restrict sum,
                                    float* __restrict sum2) {
  for (int c = 0; c < w; ++c) {
    n[c] = cw[c - 1] + cw[c] + cw[c + 1];
    sum[c] = ca[c - 1] + ca[c] + ca[c + 1];
    sum2[c] = ca[c - 1] * ca[c - 1] + ca[c] * ca[c] + ca[c + 1] * ca[c + 1];
  }
}

// Prepares one row in one pass, eight pixels at a time: per pixel the weight (1 usable: finite
// distance and amplitude, no reject flag; else 0), the amplitude (0 if unusable) and the distance
// for the minimum (+inf if unusable) and the maximum (-inf); then the horizontal 3-min / 3-max and,
// with `sums`, the horizontal 3-sums of HorizontalSums. A pixel's neighbours come from the blocks
// before and after it by in-register shifts, so each pixel is prepared once and nothing is read
// back; the sums are the same float operations in the same order as HorizontalSums (min and max
// are exact), so the values are the same bit for bit. Writes the padded weights and amplitudes
// (cw, ca: the sparse path and on-demand sums read them; the last block's lanes beyond w are the
// neutral 0, so the pad at w keeps its value), the 3-min / 3-max rows (lo, hi) and with sums the
// count, Σa and Σa² rows (n, sum, sum2); every output has room for 16 floats past w. With
// next_d not null it prefetches the next row's inputs (next_d, next_a, next_pf) as it goes.
// Measured against the three separate row loops it replaced (filters_bench, docs/benchmarks.md).
TOFCAM_HOT_LOOP void PrepareRowShifted(int w, bool sums, const float* __restrict d,
                                       const float* __restrict a, const PixelFlags* __restrict pf,
                                       const float* next_d, const float* next_a,
                                       const PixelFlags* next_pf, float* __restrict cw,
                                       float* __restrict ca, float* __restrict lo,
                                       float* __restrict hi, float* __restrict n,
                                       float* __restrict sum, float* __restrict sum2) {
  using simd::F8;
  using simd::I8;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  constexpr std::int32_t kInfBits = 0x7f800000;
  struct Block {
    F8 w, a, lo, hi;
  };
  const F8 one = F8{} + 1.0f, inf = F8{} + kInf, ninf = F8{} - kInf;
  // Block of columns [c0, c0 + 8); lanes at or beyond w are neutral.
  auto prepare = [&](int c0) __attribute__((always_inline)) {
    F8 dv, av;
    I8 fv;
    if (c0 + 8 <= w) {
      dv = simd::LoadF8(d + c0);
      av = simd::LoadF8(a + c0);
      fv = simd::LoadFlags8(pf + c0);
    } else {
      alignas(32) float ds[8] = {}, as[8] = {};
      alignas(32) std::uint16_t fs[8];
      for (int l = 0; l < 8; ++l) {
        const bool in = c0 + l < w;
        ds[l] = in ? d[c0 + l] : 0.0f;
        as[l] = in ? a[c0 + l] : 0.0f;
        fs[l] = in ? pf[c0 + l].bits() : kRejectMask;
      }
      dv = simd::LoadF8(ds);
      av = simd::LoadF8(as);
      fv = simd::LoadFlags8(fs);
    }
    // |x| < inf as integers: false for NaN and ±inf.
    const I8 usable = (simd::AbsBits(dv) < kInfBits) & (simd::AbsBits(av) < kInfBits) &
                      ((fv & static_cast<std::int32_t>(kRejectMask)) == 0);
    return Block{simd::Select(usable, one), simd::Select(usable, av), usable != 0 ? dv : inf,
                 usable != 0 ? dv : ninf};
  };
  const Block neutral{F8{}, F8{}, inf, ninf};
  // Lane i of the block before / after column c0 + i, and std::min / std::max in the scalar
  // loops' operand order (the values are never NaN). Macros rather than lambdas: clang refuses
  // lambdas taking 32-byte vectors in a function with an AVX2 clone (their ABI differs).
#define TOFCAM_LEFT(before, at) __builtin_shufflevector(before, at, 7, 8, 9, 10, 11, 12, 13, 14)
#define TOFCAM_RIGHT(at, after) __builtin_shufflevector(at, after, 1, 2, 3, 4, 5, 6, 7, 8)
  Block prev = neutral, cur = prepare(0);
  for (int c0 = 0; c0 < w; c0 += 8) {
    if (next_d != nullptr && (c0 & 15) == 0) {  // one 64-byte line per 16 pixels (32 of flags)
      __builtin_prefetch(next_d + c0);
      __builtin_prefetch(next_a + c0);
      if ((c0 & 31) == 0) __builtin_prefetch(next_pf + c0);
    }
    const Block next = c0 + 8 < w ? prepare(c0 + 8) : neutral;
    const F8 lo_l = TOFCAM_LEFT(prev.lo, cur.lo), lo_r = TOFCAM_RIGHT(cur.lo, next.lo);
    const F8 hi_l = TOFCAM_LEFT(prev.hi, cur.hi), hi_r = TOFCAM_RIGHT(cur.hi, next.hi);
    const F8 lo_lc = cur.lo < lo_l ? cur.lo : lo_l;
    const F8 hi_lc = hi_l < cur.hi ? cur.hi : hi_l;
    const F8 lo3 = lo_r < lo_lc ? lo_r : lo_lc;
    const F8 hi3 = hi_lc < hi_r ? hi_r : hi_lc;
    std::memcpy(cw + c0, &cur.w, sizeof cur.w);
    std::memcpy(ca + c0, &cur.a, sizeof cur.a);
    std::memcpy(lo + c0, &lo3, sizeof lo3);
    std::memcpy(hi + c0, &hi3, sizeof hi3);
    if (sums) {
      const F8 al = TOFCAM_LEFT(prev.a, cur.a), ar = TOFCAM_RIGHT(cur.a, next.a);
      const F8 nn = (TOFCAM_LEFT(prev.w, cur.w) + cur.w) + TOFCAM_RIGHT(cur.w, next.w);
      const F8 ss = (al + cur.a) + ar;
      const F8 qq = (al * al + cur.a * cur.a) + ar * ar;
      std::memcpy(n + c0, &nn, sizeof nn);
      std::memcpy(sum + c0, &ss, sizeof ss);
      std::memcpy(sum2 + c0, &qq, sizeof qq);
    }
    prev = cur;
    cur = next;
  }
#undef TOFCAM_LEFT
#undef TOFCAM_RIGHT
}

#if defined(TOFCAM_AVX512_FORMS)
using internal::UseAvx512Forms;
#endif

struct Thresholds {
  float contrast, floor_a, close, far, max_delta, avg_delta;
};

// The distance conditions at one pixel: the centre is usable (weight cw != 0) and lies more than
// `close` above the window minimum and `far` below its maximum (3-min / 3-max rows up, mid,
// down), with the larger and the mean margin above their thresholds. 1 or 0; integer ANDs
// instead of && keep the callers' loops free of branches.
[[gnu::always_inline]] inline unsigned DistancePass(float lu, float lm, float lv, float hu,
                                                    float hm, float hv, float dc, float cw,
                                                    const Thresholds& t) {
  const float dmin = std::min(std::min(lu, lm), lv);
  const float dmax = std::max(std::max(hu, hm), hv);
  const float to_min = dc - dmin, to_max = dmax - dc;
  return static_cast<unsigned>(cw != 0.0f) & static_cast<unsigned>(to_min > t.close) &
         static_cast<unsigned>(to_max > t.far) &
         static_cast<unsigned>(std::max(to_min, to_max) > t.max_delta) &
         static_cast<unsigned>(0.5f * (to_min + to_max) > t.avg_delta);
}

// 1 where the centre is usable and the distance conditions hold (the rows' 3-min / 3-max up,
// mid and down; `cw` the mid row's weights), else 0; returns how many (one pass, not two).
TOFCAM_HOT_LOOP std::uint32_t DistanceCandidates(
    int w, const Thresholds& t, const float* __restrict lu, const float* __restrict lm,
    const float* __restrict lv, const float* __restrict hu, const float* __restrict hm,
    const float* __restrict hv, const float* __restrict d, const float* __restrict cw,
    std::uint8_t* __restrict candidate) {
  std::uint32_t count = 0;
  for (int c = 0; c < w; ++c) {
    const unsigned pass = DistancePass(lu[c], lm[c], lv[c], hu[c], hm[c], hv[c], d[c], cw[c], t);
    candidate[c] = static_cast<std::uint8_t>(pass);
    count += pass;
  }
  return count;
}

// Population variance n·Σa² - (Σa)² over n², clamped against rounding below zero;
// std/mean >= contrast  <=>  var·n² >= (contrast·mean·n)²  (both sides >= 0), with
// mean·n = max(Σa / n, floor)·n = max(Σa, floor·n) (n > 0): no division.
[[gnu::always_inline]] inline bool ContrastAtLeast(float cnt, float sum, float sum2,
                                                   const Thresholds& t) {
  const float nn = std::max(cnt, 1.0f);
  const float var_n2 = std::max(nn * sum2 - sum * sum, 0.0f);
  const float lim = t.contrast * std::max(sum, t.floor_a * nn);
  return var_n2 >= lim * lim;
}

// The whole rule over a row in one pass (3-min / 3-max rows lu..hv, horizontal sums nu..qv, the
// mid row's weights cw), for rows with many candidates; ORs the flag into f and, when echo is
// not null, into echo (see FlyingPixelInto), and returns the number of pixels that passed the
// distance conditions (to choose the next row's form). The loop is written once and
// instantiated with and without the echo stores (a generic lambda rather than a template
// function: clang cannot multiversion templates).
TOFCAM_HOT_LOOP std::uint32_t DecideRow(int w, const Thresholds& t, const float* __restrict lu,
                                        const float* __restrict lm, const float* __restrict lv,
                                        const float* __restrict hu, const float* __restrict hm,
                                        const float* __restrict hv, const float* __restrict d,
                                        const float* __restrict cw, const float* __restrict nu,
                                        const float* __restrict nm, const float* __restrict nv,
                                        const float* __restrict su, const float* __restrict sm,
                                        const float* __restrict sv, const float* __restrict qu,
                                        const float* __restrict qm, const float* __restrict qv,
                                        PixelFlags* __restrict f, PixelFlags* __restrict echo) {
  const std::uint16_t bit = static_cast<std::uint16_t>(Flag::kFlyingPixel);
  auto rows = [&](auto with_echo) {
    std::uint32_t count = 0;
    for (int c = 0; c < w; ++c) {
      const unsigned pass = DistancePass(lu[c], lm[c], lv[c], hu[c], hm[c], hv[c], d[c], cw[c], t);
      count += pass;
      const unsigned flying =
          pass & static_cast<unsigned>(ContrastAtLeast(nu[c] + nm[c] + nv[c], su[c] + sm[c] + sv[c],
                                                       qu[c] + qm[c] + qv[c], t));
      f[c] |= PixelFlags(static_cast<std::uint16_t>(flying * bit));
      if constexpr (decltype(with_echo)::value) {
        echo[c] |= PixelFlags(static_cast<std::uint16_t>(flying * bit));
      }
    }
    return count;
  };
  return echo != nullptr ? rows(std::true_type{}) : rows(std::false_type{});
}

// DecideRow for two rows at once, the mid row m and the row v below it (3-min / 3-max rows u, m,
// v, x from the row above m to the row below v, their horizontal sums; cm, cv the two rows'
// weights). Rows m and v's streams are read once for both output rows: 24 input streams for two
// rows instead of 2 x 17. The same float operations per pixel as DecideRow. Returns the pixels
// of row v that passed the distance conditions (for the next row's form). Its x86-64-v4 clone
// (the AVX2 clone alone was no faster than DecideRow twice; the v4 clone took about 12 % less
// time on noisy frames, filters_bench SR-2 30.3 against 34.5 us) runs on AVX-512 CPUs under the
// test switch.
TOFCAM_HOT_LOOP_WIDE std::uint32_t DecideTwoRows(
    int w, const Thresholds& t, const float* __restrict lu, const float* __restrict lm,
    const float* __restrict lv, const float* __restrict lx, const float* __restrict hu,
    const float* __restrict hm, const float* __restrict hv, const float* __restrict hx,
    const float* __restrict dm, const float* __restrict dv, const float* __restrict cm,
    const float* __restrict cv, const float* __restrict nu, const float* __restrict nm,
    const float* __restrict nv, const float* __restrict nx, const float* __restrict su,
    const float* __restrict sm, const float* __restrict sv, const float* __restrict sx,
    const float* __restrict qu, const float* __restrict qm, const float* __restrict qv,
    const float* __restrict qx, PixelFlags* __restrict fm, PixelFlags* __restrict fv,
    PixelFlags* __restrict em, PixelFlags* __restrict ev) {
  const std::uint16_t bit = static_cast<std::uint16_t>(Flag::kFlyingPixel);
  // Inlined into each clone (otherwise GCC compiles the lambda once, for the baseline).
  auto rows = [&](auto with_echo) __attribute__((always_inline)) {
    std::uint32_t count = 0;
    for (int c = 0; c < w; ++c) {
      const float l_m = lm[c], l_v = lv[c], h_m = hm[c], h_v = hv[c];
      const float n_m = nm[c], n_v = nv[c], s_m = sm[c], s_v = sv[c], q_m = qm[c], q_v = qv[c];
      const unsigned pass_m = DistancePass(lu[c], l_m, l_v, hu[c], h_m, h_v, dm[c], cm[c], t);
      const unsigned pass_v = DistancePass(l_m, l_v, lx[c], h_m, h_v, hx[c], dv[c], cv[c], t);
      count += pass_v;
      const unsigned flying_m =
          pass_m & static_cast<unsigned>(
                       ContrastAtLeast(nu[c] + n_m + n_v, su[c] + s_m + s_v, qu[c] + q_m + q_v, t));
      const unsigned flying_v =
          pass_v & static_cast<unsigned>(
                       ContrastAtLeast(n_m + n_v + nx[c], s_m + s_v + sx[c], q_m + q_v + qx[c], t));
      fm[c] |= PixelFlags(static_cast<std::uint16_t>(flying_m * bit));
      fv[c] |= PixelFlags(static_cast<std::uint16_t>(flying_v * bit));
      if constexpr (decltype(with_echo)::value) {
        em[c] |= PixelFlags(static_cast<std::uint16_t>(flying_m * bit));
        ev[c] |= PixelFlags(static_cast<std::uint16_t>(flying_v * bit));
      }
    }
    return count;
  };
  return em != nullptr ? rows(std::true_type{}) : rows(std::false_type{});
}

// The rows DecideTwoRows reads and writes (same names).
struct RowPair {
  const float *lu, *lm, *lv, *lx, *hu, *hm, *hv, *hx, *dm, *dv, *cm, *cv;
  const float *nu, *nm, *nv, *nx, *su, *sm, *sv, *sx, *qu, *qm, *qv, *qx;
  PixelFlags *fm, *fv, *em, *ev;  // em, ev null: no echo
};

#if defined(TOFCAM_AVX512_FORMS)
TOFCAM_AVX512_DIAGNOSTICS_BEGIN
// DistancePass on 16 lanes as a mask, for the lanes of `usable` (the centres that are usable:
// DistancePass's cw != 0). The same operations: std::min(x, y) = vminps(y, x), std::max(x, y)
// = vmaxps(y, x).
TOFCAM_AVX512_INLINE __mmask16 DistancePass16(__mmask16 usable, __m512 lu, __m512 lm, __m512 lv,
                                              __m512 hu, __m512 hm, __m512 hv, __m512 dc,
                                              const Thresholds& t) {
  const __m512 dmin = _mm512_min_ps(lv, _mm512_min_ps(lm, lu));
  const __m512 dmax = _mm512_max_ps(hv, _mm512_max_ps(hm, hu));
  const __m512 to_min = _mm512_sub_ps(dc, dmin), to_max = _mm512_sub_ps(dmax, dc);
  __mmask16 k = _mm512_mask_cmp_ps_mask(usable, to_min, _mm512_set1_ps(t.close), _CMP_GT_OQ);
  k = _mm512_mask_cmp_ps_mask(k, to_max, _mm512_set1_ps(t.far), _CMP_GT_OQ);
  k = _mm512_mask_cmp_ps_mask(k, _mm512_max_ps(to_max, to_min), _mm512_set1_ps(t.max_delta),
                              _CMP_GT_OQ);
  return _mm512_mask_cmp_ps_mask(k,
                                 _mm512_mul_ps(_mm512_set1_ps(0.5f), _mm512_add_ps(to_min, to_max)),
                                 _mm512_set1_ps(t.avg_delta), _CMP_GT_OQ);
}

// ContrastAtLeast on 16 lanes, restricted to the lanes of k.
TOFCAM_AVX512_INLINE __mmask16 Contrast16(__mmask16 k, __m512 cnt, __m512 sum, __m512 sum2,
                                          const Thresholds& t) {
  const __m512 nn = _mm512_max_ps(_mm512_set1_ps(1.0f), cnt);
  const __m512 var_n2 = _mm512_max_ps(
      _mm512_setzero_ps(), _mm512_sub_ps(_mm512_mul_ps(nn, sum2), _mm512_mul_ps(sum, sum)));
  const __m512 lim = _mm512_mul_ps(
      _mm512_set1_ps(t.contrast), _mm512_max_ps(_mm512_mul_ps(_mm512_set1_ps(t.floor_a), nn), sum));
  return _mm512_mask_cmp_ps_mask(k, var_n2, _mm512_mul_ps(lim, lim), _CMP_GE_OQ);
}

// One row of a 16-pixel column strip, reduced horizontally: the 3-min / 3-max of the usable
// distances (+inf / -inf where none), the count, Σa and Σa² of the usable pixels, and the centre
// lanes' distance and usability.
struct Across16 {
  __m512 lo, hi, n, sum, sum2, d;
  __mmask16 usable;
};

// The address one element before p, for a masked load whose lane 0 is off at column 0. At the
// image's first pixel `p - 1` would point before the image: undefined behaviour in C++ even if
// never read. Integer arithmetic on the address is not (the conversion back is GCC's documented
// implementation-defined mapping, which these intrinsics rely on anyway), and the masked load
// never touches the element.
template <typename T>
TOFCAM_AVX512_INLINE const T* OneBefore(const T* p) {
  return reinterpret_cast<const T*>(reinterpret_cast<std::uintptr_t>(p) - sizeof(T));
}

// Row r's Across16 for columns [c0, c0 + 16) (lanes in `in`; `left` / `right` the lanes whose
// left / right neighbour lies in the image). The same flags as PrepareRowShifted's values give
// (its pad and neutral lanes are the masked-out lanes here):
// - the sums add the same terms in the same order, with masked adds where PrepareRowShifted
//   adds an unusable pixel's 0 (x + 0 = x; only the sign of a zero Σa can differ, and every
//   test on Σa is blind to it: Contrast16 squares it, or squares max(floor·n, Σa));
// - the 3-min / 3-max compare in PrepareRowShifted's order (left, then centre, then right:
//   vminps(x, y) = x < y ? x : y), so they are the same values;
// - vfpclassps finds NaN and ±inf in one operation (|x| < inf needs two).
TOFCAM_AVX512_INLINE Across16 AcrossRow16(const float* d, const float* a, const PixelFlags* pf,
                                          __mmask16 in, __mmask16 left, __mmask16 right) {
  constexpr int kNonFinite = 0x01 | 0x08 | 0x10 | 0x80;  // QNaN, +inf, -inf, SNaN
  const __m256i reject = _mm256_set1_epi16(static_cast<short>(kRejectMask));
  auto usable = [&](__mmask16 k, __m512 dv, __m512 av, const PixelFlags* fp)
      __attribute__((always_inline, target("avx512f,avx512bw,avx512vl,avx512dq"))) {
    const __mmask16 ok = _mm256_mask_testn_epi16_mask(k, _mm256_maskz_loadu_epi16(k, fp), reject);
    return static_cast<__mmask16>(
        ok & ~(_mm512_fpclass_ps_mask(dv, kNonFinite) | _mm512_fpclass_ps_mask(av, kNonFinite)));
  };
  const __m512 dl = _mm512_maskz_loadu_ps(left, OneBefore(d)), dc = _mm512_maskz_loadu_ps(in, d);
  const __m512 dr = _mm512_maskz_loadu_ps(right, d + 1);
  const __m512 al = _mm512_maskz_loadu_ps(left, OneBefore(a)), ac = _mm512_maskz_loadu_ps(in, a);
  const __m512 ar = _mm512_maskz_loadu_ps(right, a + 1);
  const __mmask16 ul = usable(left, dl, al, OneBefore(pf));
  const __mmask16 uc = usable(in, dc, ac, pf);
  const __mmask16 ur = usable(right, dr, ar, pf + 1);
  const __m512 one = _mm512_set1_ps(1.0f);
  Across16 o;
  o.lo = _mm512_mask_blend_ps(ul, _mm512_set1_ps(std::numeric_limits<float>::infinity()), dl);
  o.lo = _mm512_mask_min_ps(o.lo, uc, dc, o.lo);
  o.lo = _mm512_mask_min_ps(o.lo, ur, dr, o.lo);
  o.hi = _mm512_mask_blend_ps(ul, _mm512_set1_ps(-std::numeric_limits<float>::infinity()), dl);
  o.hi = _mm512_mask_max_ps(o.hi, uc, dc, o.hi);
  o.hi = _mm512_mask_max_ps(o.hi, ur, dr, o.hi);
  o.n = _mm512_maskz_mov_ps(ul, one);
  o.n = _mm512_mask_add_ps(o.n, uc, o.n, one);
  o.n = _mm512_mask_add_ps(o.n, ur, o.n, one);
  o.sum = _mm512_maskz_mov_ps(ul, al);
  o.sum = _mm512_mask_add_ps(o.sum, uc, o.sum, ac);
  o.sum = _mm512_mask_add_ps(o.sum, ur, o.sum, ar);
  o.sum2 = _mm512_maskz_mul_ps(ul, al, al);
  o.sum2 = _mm512_mask_add_ps(o.sum2, uc, o.sum2, _mm512_mul_ps(ac, ac));
  o.sum2 = _mm512_mask_add_ps(o.sum2, ur, o.sum2, _mm512_mul_ps(ar, ar));
  o.d = dc;
  o.usable = uc;
  return o;
}

TOFCAM_AVX512_INLINE Across16 NeutralAcross16() {
  const __m512 z = _mm512_setzero_ps();
  return Across16{_mm512_set1_ps(std::numeric_limits<float>::infinity()),
                  _mm512_set1_ps(-std::numeric_limits<float>::infinity()),
                  z,
                  z,
                  z,
                  z,
                  0};
}

// The strip form's band (FlyingPixelStrips16): the bytes of a band's rows, halo included.
constexpr std::size_t kBandBytes = std::size_t{384} << 10;

// A strip step's pixels [i, i + 16) and which of them FlyingPixelStrips16 raised.
struct RaisedLanes {
  std::size_t i;
  __mmask16 lanes;
};

// The whole rule on AVX-512 CPUs, down one 16-pixel column strip at a time: each row's
// horizontal reductions are computed once, in registers, and the three rows of a window are
// kept there as the strip moves down, so nothing is stored but the flags (the row form stores
// seven float rows a row and reads them back). The same flags bit for bit as the row form
// (AcrossRow16 says why; PortableAndAvx512FormsGiveTheSameFlags compares them). ORs the
// bit into f and, with kEcho (`raised_at`: room for a step per 16 pixels of every row), lists
// the steps that raised a bit there and returns their number, for the caller's echo: strips read
// their neighbours' columns of prior, which may be the echo image, so the echo waits.
//
// The strips run over bands of `band` rows (a band's rows and its two halo rows fit in L2):
// down a whole frame of 640 or more columns a strip takes each row's lines from L3 one by one,
// 4.6 ns a pixel at 640x480 against 0.65 at SR-2 (filters_bench). Each strip also prefetches
// the next band's lines of its columns, so the band after is in L2 when its strips start
// (filters_bench, three alternated pairs: 640x480 0.23-0.26 ms with, 0.26-0.99 ms without;
// 1 MP 0.99-1.09 against 3.2-3.4 ms).
template <bool kEcho>
TOFCAM_AVX512_TARGET std::size_t FlyingPixelStrips16(int w, int h, int band, const float* d,
                                                     const float* a, const PixelFlags* pf,
                                                     const Thresholds& t, PixelFlags* f,
                                                     RaisedLanes* raised_at) {
  std::size_t n_raised = 0;
  const __m256i bit = _mm256_set1_epi16(static_cast<short>(Flag::kFlyingPixel));
  const std::size_t sw = static_cast<std::size_t>(w);
  for (int r0 = 0; r0 < h; r0 += band) {
    const int r1 = std::min(h, r0 + band);
    for (int c0 = 0; c0 < w; c0 += 16) {
      const int left_in_row = w - c0;
      const __mmask16 in =
          left_in_row >= 16 ? __mmask16{0xFFFF} : static_cast<__mmask16>((1u << left_in_row) - 1u);
      // Lanes whose left neighbour exists (not column 0) and whose right one does (not w - 1).
      const __mmask16 left = c0 == 0 ? static_cast<__mmask16>(in & 0xFFFEu) : in;
      const __mmask16 right = left_in_row > 16
                                  ? __mmask16{0xFFFF}
                                  : static_cast<__mmask16>((1u << (left_in_row - 1)) - 1u);
      auto at = [&](int r) {
        return static_cast<std::size_t>(r) * sw + static_cast<std::size_t>(c0);
      };
      auto row = [&](int r)
          __attribute__((always_inline, target("avx512f,avx512bw,avx512vl,avx512dq"))) {
        if (r < 0 || r >= h) return NeutralAcross16();
        const std::size_t i = at(r);
        return AcrossRow16(d + i, a + i, pf + i, in, left, right);
      };
      Across16 up = row(r0 - 1), mid = row(r0);
      for (int r = r0; r < r1; ++r) {
        if (band < h && r + band < h) {
          const std::size_t next = at(r + band);
          _mm_prefetch(reinterpret_cast<const char*>(d + next), _MM_HINT_T1);
          _mm_prefetch(reinterpret_cast<const char*>(a + next), _MM_HINT_T1);
          if ((c0 & 31) == 0) {
            _mm_prefetch(reinterpret_cast<const char*>(pf + next), _MM_HINT_T1);
            _mm_prefetch(reinterpret_cast<const char*>(f + next), _MM_HINT_T1);
          }
        }
        const Across16 down = row(r + 1);
        const __mmask16 pass =
            DistancePass16(mid.usable, up.lo, mid.lo, down.lo, up.hi, mid.hi, down.hi, mid.d, t);
        const __mmask16 flying =
            Contrast16(pass, _mm512_add_ps(_mm512_add_ps(up.n, mid.n), down.n),
                       _mm512_add_ps(_mm512_add_ps(up.sum, mid.sum), down.sum),
                       _mm512_add_ps(_mm512_add_ps(up.sum2, mid.sum2), down.sum2), t);
        const std::size_t i = at(r);
        const __m256i raised = _mm256_maskz_mov_epi16(flying, bit);
        _mm256_mask_storeu_epi16(f + i, in,
                                 _mm256_or_si256(_mm256_maskz_loadu_epi16(in, f + i), raised));
        if constexpr (kEcho) {
          // Written always, kept only when a lane was raised (no branch on the flags).
          raised_at[n_raised] = RaisedLanes{i, flying};
          n_raised += flying != 0;
        }
        up = mid;
        mid = down;
      }
    }
  }
  return n_raised;
}

TOFCAM_AVX512_DIAGNOSTICS_END
#endif

// DecideTwoRows with the rows of a RowPair.
std::uint32_t DecideTwoRowsOf(int w, const Thresholds& t, const RowPair& p) {
  return DecideTwoRows(w, t, p.lu, p.lm, p.lv, p.lx, p.hu, p.hm, p.hv, p.hx, p.dm, p.dv, p.cm, p.cv,
                       p.nu, p.nm, p.nv, p.nx, p.su, p.sm, p.sv, p.sx, p.qu, p.qm, p.qv, p.qx, p.fm,
                       p.fv, p.em, p.ev);
}

// The amplitude contrast test of one candidate at column c (rows u, m, v of prepared weights and
// amplitudes).
bool HighContrast(int c, const Thresholds& t, const Prepared& u, const Prepared& m,
                  const Prepared& v) {
  auto n3 = [c](const float* x) { return x[c - 1] + x[c] + x[c + 1]; };
  auto q3 = [c](const float* x) { return x[c - 1] * x[c - 1] + x[c] * x[c] + x[c + 1] * x[c + 1]; };
  return ContrastAtLeast(n3(u.w) + n3(m.w) + n3(v.w), n3(u.a) + n3(m.a) + n3(v.a),
                         q3(u.a) + q3(m.a) + q3(v.a), t);
}

}  // namespace

void FlyingPixelInto(const MetricFrame& frame, const Image<PixelFlags>& prior,
                     const FlyingPixelOptions& o, Image<PixelFlags>& out, Image<PixelFlags>* echo) {
  if (frame.amplitude.empty()) {
    throw Error(ErrorCode::kInvalidArgument, "flying pixel filter: amplitude is empty");
  }
  const int w = frame.width(), h = frame.height();
  const Thresholds t{
      static_cast<float>(o.min_amplitude_contrast), static_cast<float>(o.amplitude_mean_floor),
      static_cast<float>(o.min_close_delta_m),      static_cast<float>(o.min_far_delta_m),
      static_cast<float>(o.min_max_delta_m),        static_cast<float>(o.min_avg_delta_m)};
  const PixelFlags* prior_px = PriorOrZeros(prior, frame.radial_distance_m.size());
#if defined(TOFCAM_AVX512_FORMS)
  if (UseAvx512Forms()) {
    // The echo waits for the end: a strip reads its neighbour strips' columns of prior.
    thread_local std::vector<RaisedLanes> raised_at;
    if (echo != nullptr) raised_at.resize(static_cast<std::size_t>(h) * ((w + 15) / 16));
    // Bands whose rows, with the two halo rows, take at most kBandBytes (14 bytes a pixel: 10 in,
    // 2 of flags out, 2 of margin), at least 8 rows; one band where the frame fits.
    const std::size_t row_bytes = static_cast<std::size_t>(w) * 14;
    const int band = static_cast<int>(std::min(
        std::max<std::size_t>(kBandBytes / row_bytes, 10) - 2, static_cast<std::size_t>(h)));
    const float* d = frame.radial_distance_m.data();
    const float* a = frame.amplitude.data();
    const std::size_t n_raised =
        echo != nullptr
            ? FlyingPixelStrips16<true>(w, h, band, d, a, prior_px, t, out.data(), raised_at.data())
            : FlyingPixelStrips16<false>(w, h, band, d, a, prior_px, t, out.data(), nullptr);
    const PixelFlags bit(Flag::kFlyingPixel);
    for (std::size_t k = 0; k < n_raised; ++k) {
      for (unsigned lanes = raised_at[k].lanes; lanes != 0; lanes &= lanes - 1) {
        (*echo)[raised_at[k].i + static_cast<unsigned>(__builtin_ctz(lanes))] |= bit;
      }
    }
    return;
  }
#endif
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const std::size_t sw = static_cast<std::size_t>(w);
  // Stream strides: each scratch stream (a padded prepared row; a min, max or sum row) starts
  // 64 bytes further into the 4 KiB page than the one before, whatever the width. With
  // 1024-pixel rows a plain stride of w (+2) floats put all 36 streams, and the frame's own
  // rows, at nearly the same page offset, where loads wait on unrelated stores (4K aliasing).
  auto skewed = [](std::size_t n) { return (n + 15) / 16 * 16 + 16; };
  const std::size_t pw = skewed(sw + 2), mw = skewed(sw);
  thread_local Scratch s;
  s.prepared.resize(kSlots * 2 * pw);
  s.minmax.resize(kSlots * 2 * mw);
  s.sums.resize(kSlots * 3 * mw);
  s.candidate.assign((sw + 7) / 8 * 8, 0);
  // Without an echo image the sparse rows echo into a scratch row nobody reads (the dense rows
  // skip the echo).
  s.echo_sink.resize(sw);
  // Slot k in 0..kNeutral; pointers at column 0 of the padded rows.
  auto prepared = [&](int k) {
    float* base = s.prepared.data() + static_cast<std::size_t>(k) * 2 * pw + 1;
    return Prepared{base, base + pw};
  };
  auto lo_of = [&](int k) { return s.minmax.data() + static_cast<std::size_t>(k) * 2 * mw; };
  auto hi_of = [&](int k) { return lo_of(k) + mw; };
  for (int k = 0; k < kRingSlots; ++k) {
    // Pads: weight 0, amplitude 0 (PrepareRowShifted keeps them).
    const Prepared p = prepared(k);
    p.w[-1] = p.a[-1] = p.w[w] = p.a[w] = 0.0f;
  }
  // The neutral row: weight, amplitude and sums 0, distances that never win.
  std::fill_n(prepared(kNeutral).w - 1, 2 * pw, 0.0f);
  std::fill(lo_of(kNeutral), lo_of(kNeutral) + sw, kInf);
  std::fill(hi_of(kNeutral), hi_of(kNeutral) + sw, -kInf);
  auto sums_of = [&](int k) { return s.sums.data() + static_cast<std::size_t>(k) * 3 * mw; };
  std::fill_n(sums_of(kNeutral), 3 * mw, 0.0f);
  int sums_row[kRingSlots] = {-1, -1, -1, -1};  // the row whose sums slot k holds
  // Slot k's sums for row r (k = kNeutral: the neutral row), computed once per row when first
  // needed.
  auto sums = [&](int k, int r) {
    float* n = sums_of(k);
    if (k != kNeutral && sums_row[k] != r) {
      const Prepared p = prepared(k);
      HorizontalSums(w, p.w, p.a, n, n + mw, n + 2 * mw);
      sums_row[k] = r;
    }
    return n;
  };

  auto slot = [h](int r) { return r >= 0 && r < h ? r % kRingSlots : kNeutral; };
  // Frames whose inputs (10 bytes a pixel) exceed half of a typical 1 MiB L2 come from L3 or DRAM:
  // there each row is a new page, where the hardware prefetcher starts again, and the loads of a
  // row's first blocks waited on memory (40 % of the row preparation at 1 MP in perf). The row
  // preparation then prefetches the next row. Smaller frames stay in L2 between calls, where the
  // prefetches only cost (filters_bench: SR-2 about 2 % slower with them, VGA 12 % faster;
  // measured with the AVX-512 row preparation that FlyingPixelStrips16 replaced, not again for
  // the portable one).
  const bool prefetch = static_cast<std::size_t>(w) * h * 10 > (std::size_t{1} << 19);
  // Row r into its slot; with_sums: its horizontal sums too (when the rows it will be decided
  // with are expected to have many candidates).
  auto prepare_row = [&](int r, bool with_sums) {
    const int k = slot(r);
    const Prepared p = prepared(k);
    float* nk = sums_of(k);
    const bool no_prefetch = r + 1 >= h || !prefetch;
    PrepareRowShifted(w, with_sums, frame.radial_distance_m.Row(r).data(),
                      frame.amplitude.Row(r).data(), prior_px + static_cast<std::size_t>(r) * sw,
                      no_prefetch ? nullptr : frame.radial_distance_m.Row(r + 1).data(),
                      no_prefetch ? nullptr : frame.amplitude.Row(r + 1).data(),
                      no_prefetch ? nullptr : prior_px + static_cast<std::size_t>(r + 1) * sw, p.w,
                      p.a, lo_of(k), hi_of(k), nk, nk + mw, nk + 2 * mw);
    sums_row[k] = with_sums ? r : -1;
  };

  const std::uint16_t bit = static_cast<std::uint16_t>(Flag::kFlyingPixel);
  std::uint8_t* candidate = s.candidate.data();
  prepare_row(0, false);
  bool dense = false;  // the previous row had many candidates
  for (int r = 0; r < h; ++r) {
    if (r + 1 < h) prepare_row(r + 1, dense);
    const int ku = slot(r - 1), km = slot(r), kv = slot(r + 1);
    const Prepared u = prepared(ku), m = prepared(km), v = prepared(kv);
    const float* d = frame.radial_distance_m.Row(r).data();
    PixelFlags* f = out.Row(r).data();
    PixelFlags* e = echo != nullptr ? echo->Row(r).data() : s.echo_sink.data();
    // Many candidates (noisy, unfiltered input): the whole rule in one vectorised pass.
    auto decide_row = [&] {
      const float* nu = sums(ku, r - 1);
      const float* nm = sums(km, r);
      const float* nv = sums(kv, r + 1);
      const std::size_t count =
          DecideRow(w, t, lo_of(ku), lo_of(km), lo_of(kv), hi_of(ku), hi_of(km), hi_of(kv), d, m.w,
                    nu, nm, nv, nu + mw, nm + mw, nv + mw, nu + 2 * mw, nm + 2 * mw, nv + 2 * mw, f,
                    echo != nullptr ? e : nullptr);
      dense = 16 * count > sw;
    };
    if (dense && r + 1 < h) {
      // Rows r and r + 1 together; row r + 2 (or the neutral row) is the lower neighbour.
      if (r + 2 < h) prepare_row(r + 2, true);
      const int kx = slot(r + 2);
      const float* nu = sums(ku, r - 1);
      const float* nm = sums(km, r);
      const float* nv = sums(kv, r + 1);
      const float* nx = sums(kx, r + 2);
      const bool with_echo = echo != nullptr;
      PixelFlags* f2 = out.Row(r + 1).data();
      const RowPair pair{lo_of(ku),
                         lo_of(km),
                         lo_of(kv),
                         lo_of(kx),
                         hi_of(ku),
                         hi_of(km),
                         hi_of(kv),
                         hi_of(kx),
                         d,
                         frame.radial_distance_m.Row(r + 1).data(),
                         m.w,
                         v.w,
                         nu,
                         nm,
                         nv,
                         nx,
                         nu + mw,
                         nm + mw,
                         nv + mw,
                         nx + mw,
                         nu + 2 * mw,
                         nm + 2 * mw,
                         nv + 2 * mw,
                         nx + 2 * mw,
                         f,
                         f2,
                         with_echo ? e : nullptr,
                         with_echo ? echo->Row(r + 1).data() : nullptr};
      const std::size_t count = DecideTwoRowsOf(w, t, pair);
      dense = 16 * count > sw;
      ++r;
      continue;
    }
    if (dense) {
      decide_row();
      continue;
    }
    const std::size_t count = DistanceCandidates(w, t, lo_of(ku), lo_of(km), lo_of(kv), hi_of(ku),
                                                 hi_of(km), hi_of(kv), d, m.w, candidate);
    if (count == 0) continue;
    if (16 * count > sw) {
      decide_row();
      continue;
    }
    // Few candidates: test them one by one, skipping eight non-candidates at a time.
    for (int c0 = 0; c0 < w; c0 += 8) {
      std::uint64_t word;
      std::memcpy(&word, candidate + c0, sizeof word);
      if (word == 0) continue;
      for (int c = c0; c < std::min(c0 + 8, w); ++c) {
        if (candidate[c] != 0 && HighContrast(c, t, u, m, v)) {
          f[c] |= PixelFlags(bit);
          e[c] |= PixelFlags(bit);
        }
      }
    }
  }
}

}  // namespace filters_internal

void FlyingPixelOptions::Validate() const {
  auto nonneg = [](double v, const char* name) {
    if (!(v >= 0.0 && v <= 1e6)) {
      throw Error(ErrorCode::kInvalidArgument, std::string("flying_pixel.") + name + " = " +
                                                   std::to_string(v) + " is outside [0, 1e6]");
    }
  };
  nonneg(min_amplitude_contrast, "min_amplitude_contrast");
  nonneg(min_close_delta_m, "min_close_delta_m");
  nonneg(min_far_delta_m, "min_far_delta_m");
  nonneg(min_max_delta_m, "min_max_delta_m");
  nonneg(min_avg_delta_m, "min_avg_delta_m");
  if (!(amplitude_mean_floor > 0.0 && amplitude_mean_floor <= 1e9)) {
    throw Error(ErrorCode::kInvalidArgument,
                "flying_pixel.amplitude_mean_floor = " + std::to_string(amplitude_mean_floor) +
                    " must be > 0");
  }
}

Image<PixelFlags> FlyingPixelFilter(const MetricFrame& frame, const FlyingPixelOptions& options) {
  options.Validate();
  filters_internal::CheckFrame(frame, "flying pixel filter");
  Image<PixelFlags> out(frame.width(), frame.height());
  filters_internal::FlyingPixelInto(frame, frame.flags, options, out);
  return out;
}

}  // namespace tofcam

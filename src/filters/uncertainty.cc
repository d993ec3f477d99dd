#include "tofcam/filters/uncertainty.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "../core/avx512_forms.h"
#include "hot_loop.h"
#include "simd.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

#if defined(TOFCAM_AVX512_FORMS)
#include <immintrin.h>
#endif

namespace tofcam {
namespace {

[[noreturn]] void Bad(const std::string& what) { throw Error(ErrorCode::kInvalidArgument, what); }

// Relative half-width of the band around step = min_jump_sigma x sqrt(s² + s_n²) where the
// squared test below cannot tell the two sides apart and the exact test decides. Each side of
// the squared test is within a few units in the last place (1e-15) of its exact value, as is
// each side of the exact test, so outside this band both tests agree; inside it lie ties in
// practice (float inputs are 1e-7 apart). No square overflows (|d|, ΔL <= 3.4e38, m <= 100).
// Where m² (s² + s_n²) is subnormal or zero (tiny m or ΔL) its relative error is larger, but it
// is then below 2.3e-308, far below the square of the smallest nonzero step (2^-149 squared,
// 1e-90), and so is the exact threshold's square: both tests say edge. A zero step is never an
// edge (0 > x is false for x >= 0) and is not sent to the exact test.
constexpr double kBand = 1e-12;

// The edge test of one neighbour as the definition states it: step > min_jump_sigma x
// sqrt(s² + s_n²) (false for a NaN step).
inline bool ExactEdgeStep(double step, double min_jump_sigma, double sc, double sn) {
  return step > min_jump_sigma * std::sqrt(sc * sc + sn * sn);
}

// One row of the default uncertainty (no extrapolated edges) from padded rows (index -1 and w
// exist): `d` the usable distances (NaN where not usable or outside the image), `s` ΔL, `unknown`
// 1 where the pixel carries one of the unknown-neighbour flags; `du`, `dd` (`su`, `sd`, `ku`,
// `kd`) the rows above and below. u = sqrt(s² + edge²) in double as the per-pixel form in
// ComputeUncertainty (max of non-negative finite values is exact in any order), +inf for an
// unusable centre or an unknown neighbour. The four edge tests compare squares (step² against
// min_jump_sigma² (s² + s_n²), no square root; four of the five square roots were the row's
// cost); a test within kBand of a tie sets `tie[c]` and the caller redoes that pixel with the
// exact tests (RedoPixel). Returns how many pixels it marked.
TOFCAM_HOT_LOOP std::uint32_t UncertaintyRow(int w, double min_jump_sigma, double edge_fraction,
                                             const float* __restrict d, const float* __restrict s,
                                             const std::uint8_t* __restrict unknown,
                                             const float* __restrict du, const float* __restrict su,
                                             const std::uint8_t* __restrict ku,
                                             const float* __restrict dd, const float* __restrict sd,
                                             const std::uint8_t* __restrict kd,
                                             float* __restrict out, std::uint8_t* __restrict tie) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const double m2 = min_jump_sigma * min_jump_sigma;
  std::uint32_t ties = 0;  // 32 bits: GCC vectorises the count
  for (int c = 0; c < w; ++c) {
    const double dc = d[c], sc = s[c];
    double edge = 0.0;
    unsigned near = 0;
    // Neighbours up, down, left, right.
    const double dn[4] = {du[c], dd[c], d[c - 1], d[c + 1]};
    const double sn[4] = {su[c], sd[c], s[c - 1], s[c + 1]};
    for (int k = 0; k < 4; ++k) {
      const double step = std::abs(dn[k] - dc);
      const double s2 = step * step, r2 = m2 * (sc * sc + sn[k] * sn[k]);
      // False for a NaN (unusable) neighbour.
      const bool edge_step = s2 > r2 * (1.0 + kBand);
      near |= static_cast<unsigned>(!edge_step & !(s2 < r2 * (1.0 - kBand)) & (step > 0.0));
      edge = std::max(edge, edge_step ? edge_fraction * step : 0.0);
    }
    const bool unbounded = (ku[c] | kd[c] | unknown[c - 1] | unknown[c + 1]) != 0;
    const float u = static_cast<float>(std::sqrt(sc * sc + edge * edge));
    out[c] = (dc == dc) && !unbounded ? u : kInf;
    tie[c] = static_cast<std::uint8_t>(near);
    ties += near;
  }
  return ties;
}

#if defined(TOFCAM_AVX512_FORMS)
TOFCAM_AVX512_DIAGNOSTICS_BEGIN
// Eight floats of a padded row (lanes beyond `lanes` 0) as doubles.
TOFCAM_AVX512_INLINE __m512d Load8(__mmask8 lanes, const float* p) {
  return _mm512_cvtps_pd(_mm256_maskz_loadu_ps(lanes, p));
}

// Lanes of eight unknown-neighbour bytes that are set.
TOFCAM_AVX512_INLINE __mmask8 Bytes8(__mmask8 lanes, const std::uint8_t* p) {
  const __m128i v = _mm_maskz_loadu_epi8(lanes, p);
  return static_cast<__mmask8>(_mm_test_epi8_mask(v, v));
}

// UncertaintyRow for AVX-512 CPUs, eight pixels (doubles) at a time, written with intrinsics:
// GCC's AVX2 clone of the row spills (four neighbours of four lanes each). The same double
// operations in the same order (separate multiplies and adds: the file is built without
// contraction), the same band and ties.
TOFCAM_AVX512_TARGET std::uint32_t UncertaintyRow8(
    int w, double min_jump_sigma, double edge_fraction, const float* __restrict d,
    const float* __restrict s, const std::uint8_t* __restrict unknown, const float* __restrict du,
    const float* __restrict su, const std::uint8_t* __restrict ku, const float* __restrict dd,
    const float* __restrict sd, const std::uint8_t* __restrict kd, float* __restrict out,
    std::uint8_t* __restrict tie) {
  const __m512d m2 = _mm512_set1_pd(min_jump_sigma * min_jump_sigma);
  const __m512d fraction = _mm512_set1_pd(edge_fraction);
  const __m512d above = _mm512_set1_pd(1.0 + kBand), below = _mm512_set1_pd(1.0 - kBand);
  const __m256 inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  std::uint32_t ties = 0;
  for (int c = 0; c < w; c += 8) {
    const __mmask8 lanes =
        w - c >= 8 ? __mmask8{0xff} : static_cast<__mmask8>((1u << (w - c)) - 1u);
    const __m512d dc = Load8(lanes, d + c), sc = Load8(lanes, s + c);
    const __m512d sc2 = _mm512_mul_pd(sc, sc);
    __m512d edge = _mm512_setzero_pd();
    __mmask8 near = 0;
    const float* dn[4] = {du + c, dd + c, d + c - 1, d + c + 1};
    const float* sn[4] = {su + c, sd + c, s + c - 1, s + c + 1};
    for (int k = 0; k < 4; ++k) {
      const __m512d step = _mm512_abs_pd(_mm512_sub_pd(Load8(lanes, dn[k]), dc));
      const __m512d snk = Load8(lanes, sn[k]);
      const __m512d s2 = _mm512_mul_pd(step, step);
      const __m512d r2 = _mm512_mul_pd(m2, _mm512_add_pd(sc2, _mm512_mul_pd(snk, snk)));
      const __mmask8 yes = _mm512_cmp_pd_mask(s2, _mm512_mul_pd(r2, above), _CMP_GT_OQ);
      const __mmask8 no = _mm512_cmp_pd_mask(s2, _mm512_mul_pd(r2, below), _CMP_LT_OQ);
      near |= static_cast<__mmask8>(~(yes | no) &
                                    _mm512_cmp_pd_mask(step, _mm512_setzero_pd(), _CMP_GT_OQ));
      edge = _mm512_max_pd(_mm512_maskz_mul_pd(yes, fraction, step), edge);
    }
    const __mmask8 unbounded = Bytes8(lanes, ku + c) | Bytes8(lanes, kd + c) |
                               Bytes8(lanes, unknown + c - 1) | Bytes8(lanes, unknown + c + 1);
    const __m256 u = _mm512_cvtpd_ps(_mm512_sqrt_pd(_mm512_add_pd(sc2, _mm512_mul_pd(edge, edge))));
    const __mmask8 finite =
        static_cast<__mmask8>(_mm512_cmp_pd_mask(dc, dc, _CMP_ORD_Q) & ~unbounded);
    _mm256_mask_storeu_ps(out + c, lanes, _mm256_mask_mov_ps(inf, finite, u));
    near &= lanes;
    _mm_mask_storeu_epi8(tie + c, lanes, _mm_maskz_set1_epi8(near, 1));
    ties += static_cast<std::uint32_t>(__builtin_popcount(near));
  }
  return ties;
}
TOFCAM_AVX512_DIAGNOSTICS_END
#endif

// UncertaintyRow8 where the CPU has AVX-512 (unless a test asked for the portable form), else
// UncertaintyRow.
std::uint32_t UncertaintyRowAnyCpu(int w, double min_jump_sigma, double edge_fraction,
                                   const float* d, const float* s, const std::uint8_t* unknown,
                                   const float* du, const float* su, const std::uint8_t* ku,
                                   const float* dd, const float* sd, const std::uint8_t* kd,
                                   float* out, std::uint8_t* tie) {
#if defined(TOFCAM_AVX512_FORMS)
  if (internal::UseAvx512Forms()) {
    return UncertaintyRow8(w, min_jump_sigma, edge_fraction, d, s, unknown, du, su, ku, dd, sd, kd,
                           out, tie);
  }
#endif
  return UncertaintyRow(w, min_jump_sigma, edge_fraction, d, s, unknown, du, su, ku, dd, sd, kd,
                        out, tie);
}

// UncertaintyRow's pixel c with the exact edge tests: its u.
float RedoPixel(int c, double min_jump_sigma, double edge_fraction, const float* d, const float* s,
                const std::uint8_t* unknown, const float* du, const float* su,
                const std::uint8_t* ku, const float* dd, const float* sd, const std::uint8_t* kd) {
  const double dc = d[c], sc = s[c];
  double edge = 0.0;
  const double dn[4] = {du[c], dd[c], d[c - 1], d[c + 1]};
  const double sn[4] = {su[c], sd[c], s[c - 1], s[c + 1]};
  for (int k = 0; k < 4; ++k) {
    const double step = std::abs(dn[k] - dc);
    const bool edge_step = ExactEdgeStep(step, min_jump_sigma, sc, sn[k]);
    edge = std::max(edge, edge_step ? edge_fraction * step : 0.0);
  }
  // Bit 0 only: UncertaintyFlags16's bytes carry more bits (kUnknownBit is bit 0).
  const bool unbounded = ((ku[c] | kd[c] | unknown[c - 1] | unknown[c + 1]) & 1) != 0;
  const float u = static_cast<float>(std::sqrt(sc * sc + edge * edge));
  return (dc == dc) && !unbounded ? u : std::numeric_limits<float>::infinity();
}

#if defined(TOFCAM_AVX512_FORMS)
TOFCAM_AVX512_DIAGNOSTICS_BEGIN
// ---------------------------------------------------------------------------------------------
// UncertaintyFilterInto's AVX-512 form: the flags straight from the frame in one pass over rows
// (three padded rows in a ring instead of padded copies of the whole frame, no u image, no
// separate flag pass), its tests in float, sixteen pixels at a time. Every decision equals the
// double definition's: a float test decides only outside kFloatBand of its tie, and a pixel
// with a test inside the band, or with an input outside the range the band's argument covers,
// is redone with RedoPixel's exact tests.

// Bits of the ring's per-pixel byte.
constexpr std::uint8_t kUnknownBit = 1;   // carries one of unknown_neighbour_flags
constexpr std::uint8_t kUnsafeBit = 2;    // usable, but a value outside the float form's range
constexpr std::uint8_t kRejectedBit = 4;  // carries a reject flag

// Relative half-width of the float tests' band. The edge test (step² against
// m² (s² + s_n²) (1 ± band)) carries at most 8 float roundings against its exact value when the
// inputs lie in the range below; the threshold test (u² = s² + fraction² max(step²) against
// max² (1 ± band), where the definition rounds u to float first) at most 11, 6.6e-7 relative.
// The double definition is within 1e-15, so outside 1e-5 of a tie both decide alike (a 15-fold
// margin). Inside it, RedoPixel decides.
constexpr float kFloatBand = 1e-5f;

// The range of a usable pixel's distance and ΔL (1e-10 <= |x| <= 1e15) in which no float square
// or product of the tests overflows (steps <= 2e15, squares <= 4e30, times m² <= 1e4) and none
// that can decide a test is subnormal (a nonzero step is >= 2^-57 = 6.9e-18, its square 4.8e-35;
// s² + s_n² >= 1e-20, times m² >= 1e-6). Pixels outside it (zero included, which real frames
// do not have on a usable pixel), and their neighbours, take the exact tests.
constexpr float kSmallest = 1e-10f, kLargest = 1e15f;

// Whether the float form covers these options: neither extrapolated nor unmixed edges (the
// per-pixel form alone has them), m² >= 1e-6 (above), max² normal, and the edge term's fraction
// 0 or not so small that fraction x step underflows.
bool FloatFormCovers(const UncertaintyOptions& o) {
  return !o.extrapolate_edges && !o.unmix_edges && o.min_jump_sigma >= 1e-3 &&
         o.max_uncertainty_m >= 1e-10 && (o.edge_fraction == 0.0 || o.edge_fraction >= 1e-6);
}

TOFCAM_AVX512_INLINE __mmask16 Lanes16(int n) {
  return n >= 16 ? __mmask16{0xffff} : static_cast<__mmask16>((1u << n) - 1u);
}

// Sixteen pixels of a padded ring row from a frame row: the distance where usable (NaN
// otherwise), ΔL, and the byte of kUnknownBit / kUnsafeBit / kRejectedBit; stored at `pd`, `ps`,
// `pk` and returned in `dv`, `sv`, `kv`. Masks are combined through compare and test write
// masks (an AND for free) rather than mask-register logic, which GCC moves through general
// registers.
TOFCAM_AVX512_INLINE void Pad16(__mmask16 lanes, const float* d, const float* s,
                                const PixelFlags* flags, std::uint16_t unknown_flags, float* pd,
                                float* ps, std::uint8_t* pk, __m512& dv, __m512& sv, __m128i& kv) {
  const __m512 raw = _mm512_maskz_loadu_ps(lanes, d);
  sv = _mm512_maskz_loadu_ps(lanes, s);
  const __m256i fv = _mm256_maskz_loadu_epi16(lanes, flags);
  const __m512 da = _mm512_abs_ps(raw), sa = _mm512_abs_ps(sv);
  const __m256i reject = _mm256_set1_epi16(static_cast<short>(kRejectMask));
  const __mmask16 rejected = _mm256_test_epi16_mask(fv, reject);
  // Not rejected, |d| and |ΔL| finite (ordered compares: false for NaN).
  const __m512 inf = _mm512_set1_ps(std::numeric_limits<float>::infinity());
  const __mmask16 usable = _mm512_mask_cmp_ps_mask(
      _mm512_mask_cmp_ps_mask(_mm256_testn_epi16_mask(fv, reject), da, inf, _CMP_LT_OQ), sa, inf,
      _CMP_LT_OQ);
  // Usable with the smaller of |d|, |ΔL| below kSmallest or the larger above kLargest.
  const __mmask16 unsafe = static_cast<__mmask16>(
      _mm512_mask_cmp_ps_mask(usable, _mm512_min_ps(da, sa), _mm512_set1_ps(kSmallest),
                              _CMP_LT_OQ) |
      _mm512_mask_cmp_ps_mask(usable, _mm512_max_ps(da, sa), _mm512_set1_ps(kLargest), _CMP_GT_OQ));
  dv = _mm512_mask_mov_ps(_mm512_set1_ps(std::numeric_limits<float>::quiet_NaN()), usable, raw);
  const __mmask16 unknown =
      _mm256_test_epi16_mask(fv, _mm256_set1_epi16(static_cast<short>(unknown_flags)));
  kv = _mm_maskz_set1_epi8(unknown, kUnknownBit);
  kv = _mm_mask_add_epi8(kv, unsafe, kv, _mm_set1_epi8(kUnsafeBit));
  kv = _mm_mask_add_epi8(kv, rejected, kv, _mm_set1_epi8(kRejectedBit));
  _mm512_mask_storeu_ps(pd, lanes, dv);
  _mm512_mask_storeu_ps(ps, lanes, sv);
  _mm_mask_storeu_epi8(pk, lanes, kv);
}

// One padded ring row from a frame row (Pad16 over the row).
TOFCAM_AVX512_TARGET void PadRow16(int w, const float* d, const float* s, const PixelFlags* flags,
                                   std::uint16_t unknown_flags, float* pd, float* ps,
                                   std::uint8_t* pk) {
  for (int c = 0; c < w; c += 16) {
    __m512 dv, sv;
    __m128i kv;
    Pad16(Lanes16(w - c), d + c, s + c, flags + c, unknown_flags, pd + c, ps + c, pk + c, dv, sv,
          kv);
  }
}

// A frame row and the ring row it is padded into.
struct RowIn {
  const float* d;
  const float* s;
  const PixelFlags* flags;
  float* pd;
  float* ps;
  std::uint8_t* pk;
  // The frame row after it, prefetched as it is padded (null: none, or a frame small enough to
  // stay in L2).
  const float* next_d = nullptr;
  const float* next_s = nullptr;
  const PixelFlags* next_flags = nullptr;
};

// kLowConfidence of one row: the float tests of UncertaintyRow on three padded ring rows, the
// row (`d`, `s`, `k`) and the one above (`du`, `su`, `ku`) padded before, the one below padded
// from the frame in the same loop (`below`; its `d`... null below the last row, whose padding
// `pd`... is read instead), so that the frame's reads overlap the arithmetic. Pixels to redo
// exactly get tie[c] = 1; returns how many.
//
// Per neighbour: s2 = step² against r2 = m² (s² + s_n²) scaled by 1 ± kFloatBand (the scale
// folded into m²); an edge where s2 > r2 (1 + band), none where !(s2 >= r2 (1 - band)) (also for
// a NaN step: an unusable neighbour), near a tie otherwise. The edge term is fraction x the
// largest edge step, so u² = s² + fraction² max(s2) (fraction >= 0: the largest product is the
// product with the largest step, as in the double definition).
TOFCAM_AVX512_TARGET std::uint32_t FlagRow16(
    int w, float m2, float fraction, float max2, std::uint16_t unknown_flags,
    const float* __restrict d, const float* __restrict s, const std::uint8_t* __restrict k,
    const float* __restrict du, const float* __restrict su, const std::uint8_t* __restrict ku,
    const RowIn& below, PixelFlags* __restrict out, std::uint8_t* __restrict tie) {
  const __m512 m2_above = _mm512_set1_ps(m2 * (1.0f + kFloatBand));
  const __m512 m2_below = _mm512_set1_ps(m2 * (1.0f - kFloatBand));
  const __m512 fraction2 = _mm512_set1_ps(fraction * fraction);
  const __m512 max_above = _mm512_set1_ps(max2 * (1.0f + kFloatBand));
  const __m512 max_below = _mm512_set1_ps(max2 * (1.0f - kFloatBand));
  const __m256i low_bit = _mm256_set1_epi16(static_cast<short>(Flag::kLowConfidence));
  const __m512 one = _mm512_set1_ps(1.0f);
  std::uint32_t ties = 0;
  for (int c = 0; c < w; c += 16) {
    const __mmask16 lanes = Lanes16(w - c);
    __m512 dd, sd;
    __m128i kd;
    if (below.next_d != nullptr) {
      _mm_prefetch(reinterpret_cast<const char*>(below.next_d + c), _MM_HINT_T0);
      _mm_prefetch(reinterpret_cast<const char*>(below.next_s + c), _MM_HINT_T0);
      if ((c & 31) == 0) {
        _mm_prefetch(reinterpret_cast<const char*>(below.next_flags + c), _MM_HINT_T0);
      }
    }
    if (below.d != nullptr) {
      Pad16(lanes, below.d + c, below.s + c, below.flags + c, unknown_flags, below.pd + c,
            below.ps + c, below.pk + c, dd, sd, kd);
    } else {
      dd = _mm512_maskz_loadu_ps(lanes, below.pd + c);
      sd = _mm512_maskz_loadu_ps(lanes, below.ps + c);
      kd = _mm_maskz_loadu_epi8(lanes, below.pk + c);
    }
    const __m512 dc = _mm512_maskz_loadu_ps(lanes, d + c), sc = _mm512_maskz_loadu_ps(lanes, s + c);
    const __m512 sc2 = _mm512_mul_ps(sc, sc);
    __m512 edge2 = _mm512_setzero_ps();  // largest squared edge step
    // Nonzero where the pixel is to be redone exactly: a test near its tie, an unsafe value
    // among the five pixels, u near the threshold (kept in a vector: see Pad16).
    __m512 redo_v = _mm512_setzero_ps();
    const __m512 dn[4] = {_mm512_maskz_loadu_ps(lanes, du + c), dd,
                          _mm512_maskz_loadu_ps(lanes, d + c - 1),
                          _mm512_maskz_loadu_ps(lanes, d + c + 1)};
    const __m512 sn[4] = {_mm512_maskz_loadu_ps(lanes, su + c), sd,
                          _mm512_maskz_loadu_ps(lanes, s + c - 1),
                          _mm512_maskz_loadu_ps(lanes, s + c + 1)};
    for (int n = 0; n < 4; ++n) {
      const __m512 step = _mm512_sub_ps(dn[n], dc);
      const __m512 s2 = _mm512_mul_ps(step, step);
      const __m512 sum = _mm512_fmadd_ps(sn[n], sn[n], sc2);
      const __m512 r2_above = _mm512_mul_ps(m2_above, sum), r2_below = _mm512_mul_ps(m2_below, sum);
      const __mmask16 yes = _mm512_cmp_ps_mask(s2, r2_above, _CMP_GT_OQ);
      edge2 = _mm512_mask_max_ps(edge2, yes, edge2, s2);
      // r2 (1 - band) <= s2 <= r2 (1 + band) (false for a NaN step: an unusable neighbour).
      const __mmask16 near = _mm512_mask_cmp_ps_mask(_mm512_cmp_ps_mask(s2, r2_above, _CMP_LE_OQ),
                                                     s2, r2_below, _CMP_GE_OQ);
      redo_v = _mm512_mask_mov_ps(redo_v, near, one);
    }
    const __m128i kc = _mm_maskz_loadu_epi8(lanes, k + c);
    const __m128i around = _mm_or_si128(_mm_or_si128(_mm_maskz_loadu_epi8(lanes, ku + c), kd),
                                        _mm_or_si128(_mm_maskz_loadu_epi8(lanes, k + c - 1),
                                                     _mm_maskz_loadu_epi8(lanes, k + c + 1)));
    redo_v = _mm512_mask_mov_ps(
        redo_v, _mm_test_epi8_mask(_mm_or_si128(around, kc), _mm_set1_epi8(kUnsafeBit)), one);
    // Judged (in the row, not rejected), and of those the ones with a finite u: a usable centre
    // (its distance not NaN) without an unknown neighbour.
    const __mmask16 judged = _mm_mask_testn_epi8_mask(lanes, kc, _mm_set1_epi8(kRejectedBit));
    const __mmask16 finite = _mm512_mask_cmp_ps_mask(
        _mm_mask_testn_epi8_mask(judged, around, _mm_set1_epi8(kUnknownBit)), dc, dc, _CMP_ORD_Q);
    const __m512 u2 = _mm512_fmadd_ps(fraction2, edge2, sc2);
    const __mmask16 close = _mm512_mask_cmp_ps_mask(_mm512_cmp_ps_mask(u2, max_above, _CMP_LE_OQ),
                                                    u2, max_below, _CMP_GE_OQ);
    redo_v = _mm512_mask_mov_ps(redo_v, close, one);
    const __mmask16 redo =
        _mm512_mask_cmp_ps_mask(finite, redo_v, _mm512_setzero_ps(), _CMP_NEQ_OQ);
    // Redone pixels are overwritten by the caller.
    const __mmask16 low = static_cast<__mmask16>(
        _kandn_mask16(finite, judged) | _mm512_mask_cmp_ps_mask(finite, u2, max_above, _CMP_GT_OQ));
    _mm256_mask_storeu_epi16(out + c, lanes, _mm256_maskz_mov_epi16(low, low_bit));
    _mm_mask_storeu_epi8(tie + c, lanes, _mm_maskz_set1_epi8(redo, 1));
    ties += static_cast<std::uint32_t>(__builtin_popcount(redo));
  }
  return ties;
}

// UncertaintyFilterInto's AVX-512 form (FloatFormCovers(options), frame checked), into `out` (the
// frame's size; every pixel written).
void UncertaintyFlags16(const MetricFrame& frame, const UncertaintyOptions& options,
                        Image<PixelFlags>& out) {
  const int w = frame.width(), h = frame.height();
  const std::size_t pw = static_cast<std::size_t>(w) + 2;
  // Four ring rows: three in use and an all-padding row above the first and below the last.
  thread_local std::vector<float> pd, ps;
  thread_local std::vector<std::uint8_t> pk, tie;
  pd.assign(4 * pw, std::numeric_limits<float>::quiet_NaN());
  ps.assign(4 * pw, 0.0f);
  pk.assign(4 * pw, 0);
  tie.resize(static_cast<std::size_t>(w));
  const auto ring = [&](int r) {
    return (r < 0 || r >= h) ? 3 * pw + 1 : static_cast<std::size_t>(r % 3) * pw + 1;
  };
  const double m = options.min_jump_sigma;
  const auto m2 = static_cast<float>(m * m);
  const auto max = static_cast<float>(options.max_uncertainty_m);
  const std::uint16_t unknown = options.unknown_neighbour_flags;
  // Frames whose inputs (10 bytes a pixel) exceed half of a typical 1 MiB L2 come from L3 or
  // DRAM, each row a new page where the hardware prefetcher starts again: there the padding
  // prefetches the next row (filters_bench, three alternated pairs: 640x480 0.40-0.45 ->
  // 0.25-0.29 ms, 1 MP 1.88-2.16 -> 1.01-1.17 ms; docs/benchmarks.md).
  const bool prefetch = static_cast<std::size_t>(w) * h * 10 > (std::size_t{1} << 19);
  PadRow16(w, frame.radial_distance_m.Row(0).data(), frame.delta_l_m.Row(0).data(),
           frame.flags.Row(0).data(), unknown, &pd[ring(0)], &ps[ring(0)], &pk[ring(0)]);
  for (int r = 0; r < h; ++r) {
    const std::size_t up = ring(r - 1), mid = ring(r), down = ring(r + 1);
    RowIn below{nullptr, nullptr, nullptr, &pd[down], &ps[down], &pk[down]};
    if (r + 1 < h) {
      below.d = frame.radial_distance_m.Row(r + 1).data();
      below.s = frame.delta_l_m.Row(r + 1).data();
      below.flags = frame.flags.Row(r + 1).data();
      if (prefetch && r + 2 < h) {
        below.next_d = frame.radial_distance_m.Row(r + 2).data();
        below.next_s = frame.delta_l_m.Row(r + 2).data();
        below.next_flags = frame.flags.Row(r + 2).data();
      }
    }
    PixelFlags* row = out.Row(r).data();
    const std::uint32_t ties =
        FlagRow16(w, m2, static_cast<float>(options.edge_fraction), max * max, unknown, &pd[mid],
                  &ps[mid], &pk[mid], &pd[up], &ps[up], &pk[up], below, row, tie.data());
    for (int c = 0; ties > 0 && c < w; ++c) {
      if (tie[static_cast<std::size_t>(c)] == 0) continue;
      const float u = RedoPixel(c, m, options.edge_fraction, &pd[mid], &ps[mid], &pk[mid], &pd[up],
                                &ps[up], &pk[up], &pd[down], &ps[down], &pk[down]);
      row[c] = PixelFlags(static_cast<std::uint16_t>(
          u <= max ? 0 : static_cast<std::uint16_t>(Flag::kLowConfidence)));
    }
  }
}
TOFCAM_AVX512_DIAGNOSTICS_END
#endif

// One row of the padded inputs of UncertaintyRow: the distance where the pixel is usable (no
// reject flag, finite distance and ΔL; NaN otherwise), ΔL, and the unknown-neighbour mask.
TOFCAM_HOT_LOOP void PadRow(int w, const float* __restrict d, const float* __restrict s,
                            const PixelFlags* __restrict flags, std::uint16_t unknown_flags,
                            float* __restrict pd, float* __restrict ps,
                            std::uint8_t* __restrict pk) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (int c = 0; c < w; ++c) {
    const bool usable = ((flags[c].bits() & kRejectMask) == 0) & (std::abs(d[c]) < kInf) &
                        (std::abs(s[c]) < kInf);  // false for NaN and inf
    pd[c] = usable ? d[c] : std::numeric_limits<float>::quiet_NaN();
    ps[c] = s[c];
    pk[c] = static_cast<std::uint8_t>((flags[c].bits() & unknown_flags) != 0);
  }
}

// kLowConfidence where a pixel without a reject flag has u above `max` (or u NaN).
TOFCAM_HOT_LOOP void FlagRow(std::size_t n, const float* __restrict u,
                             const PixelFlags* __restrict flags, float max,
                             PixelFlags* __restrict out) {
  const auto bit = static_cast<std::uint16_t>(Flag::kLowConfidence);
  for (std::size_t i = 0; i < n; ++i) {
    const bool low = ((flags[i].bits() & kRejectMask) == 0) & !(u[i] <= max);
    out[i] = PixelFlags(static_cast<std::uint16_t>(low ? bit : 0));
  }
}

}  // namespace

void UncertaintyOptions::Validate() const {
  if (!(max_uncertainty_m > 0.0 && max_uncertainty_m <= 100.0)) {
    Bad("uncertainty.max_uncertainty_m = " + std::to_string(max_uncertainty_m) +
        " must be in (0, 100]");
  }
  if (!(edge_fraction >= 0.0 && edge_fraction <= 1.0)) {
    Bad("uncertainty.edge_fraction = " + std::to_string(edge_fraction) + " must be in [0, 1]");
  }
  if (!(min_jump_sigma > 0.0 && min_jump_sigma <= 100.0)) {
    Bad("uncertainty.min_jump_sigma = " + std::to_string(min_jump_sigma) + " must be in (0, 100]");
  }
}

namespace {

// The noise term's square where the neighbours predict a pixel (PosteriorOfReading's
// operations, branch-free so that the loop vectorises): m² + v, or v with `judge_combination`;
// ΔL² where the posterior is not defined (no prediction, ΔL not positive, a non-finite value).
TOFCAM_HOT_LOOP void PredictedNoiseSquared(std::size_t n, const float* __restrict d,
                                           const float* __restrict s, const float* __restrict p,
                                           const float* __restrict sp, bool judge_combination,
                                           double* __restrict out) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    const double dc = d[i], sc = s[i], pc = p[i], spc = sp[i];
    const bool defined = (sc > 0.0) & (spc > 0.0) & (std::abs(dc) < kInf) & (std::abs(pc) < kInf) &
                         (sc < kInf) & (spc < kInf);
    const double ratio = spc / sc;
    const double gain = 1.0 / (1.0 + ratio * ratio);
    const double a = std::min(sc, spc), b = std::max(sc, spc);
    const double mean = (dc - pc) * gain;
    const double v = a * a / (1.0 + (a / b) * (a / b));
    const double n2 = judge_combination ? v : mean * mean + v;
    out[i] = defined ? n2 : sc * sc;
  }
}

void CheckInput(const MetricFrame& frame, const UncertaintyOptions& options,
                const NeighbourPrediction* prediction) {
  options.Validate();
  const int w = frame.width(), h = frame.height();
  if (w <= 0 || h <= 0) Bad("uncertainty: empty frame");
  if (!frame.delta_l_m.SameSize(w, h) || !frame.flags.SameSize(w, h)) {
    Bad("uncertainty: the frame needs ΔL and flags of its size (enable the accuracy stage)");
  }
  if (prediction != nullptr &&
      (!prediction->distance_m.SameSize(w, h) || !prediction->sigma_m.SameSize(w, h))) {
    throw Error(ErrorCode::kMismatch, "uncertainty: the neighbour prediction is " +
                                          std::to_string(prediction->distance_m.width()) + "x" +
                                          std::to_string(prediction->distance_m.height()) +
                                          ", the frame " + std::to_string(w) + "x" +
                                          std::to_string(h));
  }
}

}  // namespace

Image<float> ComputeUncertainty(const MetricFrame& frame, const UncertaintyOptions& options,
                                const NeighbourPrediction* prediction) {
  CheckInput(frame, options, prediction);
  const int w = frame.width(), h = frame.height();
  constexpr float kInf = std::numeric_limits<float>::infinity();
  auto usable = [&](std::size_t i) {
    return !frame.flags[i].Any(kRejectMask) && std::isfinite(frame.radial_distance_m[i]) &&
           std::isfinite(frame.delta_l_m[i]);
  };
  // How far pixel i lies off the straight line through its two neighbours in direction
  // (dr, dc), m: 0 when that deviation is within min_jump_sigma of its σ (sqrt(σ_i² + 4 σ_a² +
  // σ_b²)); NaN when either neighbour is outside the image or unusable.
  const auto off_line = [&](int r, int c, int dr, int dc, std::size_t i) -> double {
    const int r1 = r + dr, c1 = c + dc, r2 = r + 2 * dr, c2 = c + 2 * dc;
    if (r2 < 0 || r2 >= h || c2 < 0 || c2 >= w) return std::numeric_limits<double>::quiet_NaN();
    const std::size_t a = static_cast<std::size_t>(r1) * w + c1;
    const std::size_t b = static_cast<std::size_t>(r2) * w + c2;
    if (!usable(a) || !usable(b)) return std::numeric_limits<double>::quiet_NaN();
    const double dev = std::abs(static_cast<double>(frame.radial_distance_m[i]) -
                                2.0 * frame.radial_distance_m[a] + frame.radial_distance_m[b]);
    const double si = frame.delta_l_m[i], sa = frame.delta_l_m[a], sb = frame.delta_l_m[b];
    return dev > options.min_jump_sigma * std::sqrt(si * si + 4 * sa * sa + sb * sb) ? dev : 0.0;
  };
  // UncertaintyOptions::unmix_edges. A pixel's phasor is amplitude x e^(i 4π f d / c); an edge
  // pixel's is the mix t z_a + (1 - t) z_j of its own side's neighbour a and the neighbour j
  // across the step, t the share of its area on its own side, by least squares.
  const double wavenumber = 4.0 * kPi * frame.info.modulation_frequency_hz / kSpeedOfLightMPerS;
  const bool can_unmix = options.unmix_edges && frame.amplitude.SameSize(w, h) &&
                         std::isfinite(wavenumber) && wavenumber > 0.0;
  const auto phasor = [&](std::size_t q) {
    return std::polar(static_cast<double>(frame.amplitude[q]),
                      wavenumber * static_cast<double>(frame.radial_distance_m[q]));
  };
  // The other side may be a pixel a filter rejected as too noisy or inconsistent: a dim far
  // surface behind a bright near one reads noise in distance, but its phasor is still small,
  // and that is what the mix needs. Not a clipped or invalid one: its amplitude is no
  // measurement (importers also mark unknown amplitudes invalid).
  const auto readable = [&](std::size_t q) {
    return !frame.flags[q].Any(static_cast<std::uint16_t>(Flag::kInvalid) |
                               static_cast<std::uint16_t>(Flag::kSaturated)) &&
           std::isfinite(frame.radial_distance_m[q]) && std::isfinite(frame.delta_l_m[q]) &&
           std::isfinite(frame.amplitude[q]) && frame.amplitude[q] > 0.0f;
  };
  // t for pixel i between a and j (j readable), less min_jump_sigma times its σ: the share of
  // i's area on its own side that the phasors show beyond their noise. NaN where i's or a's
  // amplitude is not positive and finite or the two sides' phasors lie too close to decide (the
  // two tests below). Each phasor's σ (per component) is its amplitude x its phase σ, ΔL x the
  // wavenumber; after the frame pair ΔL is the two frames' combined σ while the phasor is the
  // current frame's, so the two tests and the margin are up to sqrt 2 lenient there. To first
  // order t's variance is (var_i + t² var_a + (1 - t)² var_j) / |z_a - z_j|²: each phasor's
  // noise projected on the line between the two sides.
  const auto own_share = [&](std::size_t i, std::size_t a, std::size_t j) {
    constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
    for (const std::size_t q : {i, a}) {
      const float amp = frame.amplitude[q];
      if (!(std::isfinite(amp) && amp > 0.0f)) return kNaN;
    }
    const std::complex<double> zi = phasor(i), za = phasor(a), zj = phasor(j);
    const std::complex<double> across = za - zj;
    const double n2 = std::norm(across);
    const auto var = [&](std::size_t q) {
      const double sigma =
          static_cast<double>(frame.amplitude[q]) * frame.delta_l_m[q] * wavenumber;
      return sigma * sigma;
    };
    const double var_i = var(i), var_a = var(a), var_j = var(j);
    const double m2 = options.min_jump_sigma * options.min_jump_sigma;
    if (!std::isfinite(n2) || !(n2 > m2 * (var_i + var_a + var_j))) return kNaN;
    // Nor where the phasors lie too close for a pixel wholly on its own side (t = 1, σ_t² =
    // (var_i + var_a) / n2) to clear the margin when its t̂ falls min_jump_sigma σ_t short:
    // 1 - 1/2 must exceed 2 m σ_t, or a pixel beside a small step would be charged it by its
    // noise alone.
    if (!(n2 > 16.0 * m2 * (var_i + var_a))) return kNaN;
    const double t = std::real((zi - zj) * std::conj(across)) / n2;
    const double t_var = (var_i + t * t * var_a + (1.0 - t) * (1.0 - t) * var_j) / n2;
    return t - options.min_jump_sigma * std::sqrt(t_var);
  };
  // The unmixing's edge term of usable pixel i at (r, c): the largest step to a readable
  // 4-neighbour j across which i's area is not shown (beyond min_jump_sigma of the share's σ)
  // to lie more than half on its own side, the opposite neighbour a; 0 when there is none. Where
  // the share is 1/2 within its noise, so may be the centre's side: a pixel that reads its own
  // side is trusted only when most of its area demonstrably lies there. a must be usable and
  // read within half the step of i (else i lies between the two sides, a flying pixel, for the
  // other edge terms to judge). A usable j must pass the edge test (a step beyond
  // min_jump_sigma combined σ, the same test as the other edge terms', so that the caller can
  // skip pixels without such a neighbour) and leave the line through a and i by as much (σ of
  // d_j - 2 d_i + d_a): on a slope a pixel's phasor is its neighbours' mean, t = 1/2, which
  // says nothing of an edge. A rejected j reads noise in distance, so only its phasor counts.
  const auto unmix_term = [&](int r, int c, std::size_t i) {
    double term = 0.0;
    const double di = frame.radial_distance_m[i], si = frame.delta_l_m[i];
    const int dr[4] = {-1, 1, 0, 0}, dc[4] = {0, 0, -1, 1};
    for (int k = 0; k < 4; ++k) {
      const int rj = r + dr[k], cj = c + dc[k], ra = r - dr[k], ca = c - dc[k];
      if (rj < 0 || rj >= h || cj < 0 || cj >= w || ra < 0 || ra >= h || ca < 0 || ca >= w) {
        continue;
      }
      const std::size_t j = static_cast<std::size_t>(rj) * w + cj;
      const std::size_t a = static_cast<std::size_t>(ra) * w + ca;
      if (!readable(j)) continue;
      const double step = std::abs(frame.radial_distance_m[j] - di);
      const double sj = frame.delta_l_m[j];
      if (!usable(a) || !(std::abs(frame.radial_distance_m[a] - di) <= 0.5 * step)) continue;
      if (usable(j)) {
        const double sa = frame.delta_l_m[a];
        const double bend =
            std::abs(frame.radial_distance_m[j] - 2.0 * di + frame.radial_distance_m[a]);
        if (!(step > options.min_jump_sigma * std::sqrt(si * si + sj * sj)) ||
            !(bend > options.min_jump_sigma * std::sqrt(sj * sj + 4.0 * si * si + sa * sa))) {
          continue;
        }
      }
      if (own_share(i, a, j) < 0.5) term = std::max(term, step);
    }
    return term;
  };
  // The noise term's square: ΔL², or where the neighbours predict the pixel what
  // options.judge_combination asks for.
  // With a prediction, the noise term's square of every pixel in one vectorised pass first.
  thread_local std::vector<double> predicted_noise2;
  if (prediction != nullptr) {
    predicted_noise2.resize(frame.radial_distance_m.size());
    PredictedNoiseSquared(frame.radial_distance_m.size(), frame.radial_distance_m.data(),
                          frame.delta_l_m.data(), prediction->distance_m.data(),
                          prediction->sigma_m.data(), options.judge_combination,
                          predicted_noise2.data());
  }
  const auto noise2 = [&](std::size_t i, double s) {
    return prediction == nullptr ? s * s : predicted_noise2[i];
  };
  Image<float> out(w, h, kInf);
  if (!options.extrapolate_edges && !options.unmix_edges && prediction == nullptr) {
    // Padded rows (one pixel each side; rows outside the image all padding): distances NaN
    // where not usable, ΔL, and the unknown-neighbour mask.
    const std::size_t pw = static_cast<std::size_t>(w) + 2;
    thread_local std::vector<float> pd, ps;
    thread_local std::vector<std::uint8_t> pk;
    const std::size_t rows = static_cast<std::size_t>(h) + 2;
    pd.assign(rows * pw, std::numeric_limits<float>::quiet_NaN());
    ps.assign(rows * pw, 0.0f);
    pk.assign(rows * pw, 0);
    for (int r = 0; r < h; ++r) {
      const std::size_t o = (static_cast<std::size_t>(r) + 1) * pw + 1;
      PadRow(w, frame.radial_distance_m.Row(r).data(), frame.delta_l_m.Row(r).data(),
             frame.flags.Row(r).data(), options.unknown_neighbour_flags, &pd[o], &ps[o], &pk[o]);
    }
    thread_local std::vector<std::uint8_t> tie;
    tie.resize(static_cast<std::size_t>(w));
    for (int r = 0; r < h; ++r) {
      const std::size_t up = static_cast<std::size_t>(r) * pw + 1, mid = up + pw, down = mid + pw;
      float* row = out.Row(r).data();
      const std::uint32_t ties = UncertaintyRowAnyCpu(
          w, options.min_jump_sigma, options.edge_fraction, &pd[mid], &ps[mid], &pk[mid], &pd[up],
          &ps[up], &pk[up], &pd[down], &ps[down], &pk[down], row, tie.data());
      for (int c = 0; ties > 0 && c < w; ++c) {
        if (tie[static_cast<std::size_t>(c)] == 0) continue;
        row[c] = RedoPixel(c, options.min_jump_sigma, options.edge_fraction, &pd[mid], &ps[mid],
                           &pk[mid], &pd[up], &ps[up], &pk[up], &pd[down], &ps[down], &pk[down]);
      }
    }
    return out;
  }
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      if (!usable(i)) continue;
      const double d = frame.radial_distance_m[i], s = frame.delta_l_m[i];
      double edge = 0.0;  // m
      // Whether a neighbour could be the other side of an unmixed edge (a rejected one, or an
      // edge step): the unmixing looks at no other pixel, and most pixels have none.
      bool unmix_candidate = false;
      const int dr[4] = {-1, 1, 0, 0}, dc[4] = {0, 0, -1, 1};
      for (int k = 0; k < 4; ++k) {
        const int rr = r + dr[k], cc = c + dc[k];
        if (rr < 0 || rr >= h || cc < 0 || cc >= w) continue;
        const std::size_t j = static_cast<std::size_t>(rr) * w + cc;
        if (frame.flags[j].Any(options.unknown_neighbour_flags)) {
          edge = std::numeric_limits<double>::infinity();
          break;
        }
        if (!usable(j)) {
          unmix_candidate = true;
          continue;
        }
        const double dj = frame.radial_distance_m[j];
        const double step = std::abs(dj - d);
        const double sj = frame.delta_l_m[j];
        if (!(step > options.min_jump_sigma * std::sqrt(s * s + sj * sj))) continue;
        unmix_candidate = true;
        double e = options.edge_fraction * step;
        if (options.extrapolate_edges) {
          // The step's other side is the neighbour's business; this pixel is wrong only as far
          // as it leaves its own side's surface (a mixed pixel) or that is unknown.
          const double dev = off_line(r, c, -dr[k], -dc[k], i);
          if (!std::isnan(dev)) e = dev;
        }
        edge = std::max(edge, e);
      }
      if (std::isinf(edge)) continue;  // next to a clipped pixel: unbounded
      if (can_unmix && unmix_candidate) edge = std::max(edge, unmix_term(r, c, i));
      out[i] = static_cast<float>(std::sqrt(noise2(i, s) + edge * edge));
    }
  }
  return out;
}

Image<PixelFlags> UncertaintyFilter(const MetricFrame& frame, const UncertaintyOptions& options,
                                    const NeighbourPrediction* prediction) {
  Image<PixelFlags> out;
  UncertaintyFilterInto(frame, options, out, prediction);
  return out;
}

void UncertaintyFilterInto(const MetricFrame& frame, const UncertaintyOptions& options,
                           Image<PixelFlags>& out, const NeighbourPrediction* prediction) {
#if defined(TOFCAM_AVX512_FORMS)
  if (internal::UseAvx512Forms() && FloatFormCovers(options) && prediction == nullptr) {
    CheckInput(frame, options, nullptr);
    if (!out.SameSize(frame.radial_distance_m))
      out = Image<PixelFlags>(frame.width(), frame.height());
    UncertaintyFlags16(frame, options, out);
    return;
  }
#endif
  const Image<float> u = ComputeUncertainty(frame, options, prediction);
  if (!out.SameSize(frame.radial_distance_m))
    out = Image<PixelFlags>(frame.width(), frame.height());
  // Rejected pixels (u = inf) already carry their reason; the others are judged (u = inf
  // there: next to a clipped pixel, or no ΔL).
  FlagRow(u.size(), u.data(), frame.flags.data(), static_cast<float>(options.max_uncertainty_m),
          out.data());
}

}  // namespace tofcam

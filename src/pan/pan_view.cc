#include "tofcam/pan/pan_view.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "../core/avx512_forms.h"
#include "../core/fast_atan2.h"
#include "../filters/hot_loop.h"
#include "../pipeline/stage_kernels.h"
#include "pan_cells.h"
#include "tofcam/core/error.h"
#include "tofcam/core/pixel_flags.h"
#include "tofcam/core/units.h"

#if defined(TOFCAM_AVX512_FORMS)
#include <immintrin.h>
#endif

namespace tofcam {
namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
constexpr double kDeg = kPi / 180.0;

// Points per chunk: the chunk's scratch (about 41 bytes a point, 170 KB) stays in the core's L2.
constexpr std::size_t kChunk = 4096;

// The camera-frame point d x ray (NaN where `nan_mask` or a non-finite d says so, as
// MakePointCloud) moved into the base frame (r * p + t, the same float operations as
// TransformPointCloud), whether it is valid (no reject flag, finite), and its squared distance
// from the rotation centre in double (each square exact, two roundings): the z-buffer's key.
TOFCAM_HOT_LOOP_WIDE void BasePoints(std::size_t n, const float* __restrict d,
                                     const std::uint16_t* __restrict flags, std::uint16_t nan_mask,
                                     const float* __restrict rx, const float* __restrict ry,
                                     const float* __restrict rz, const float* __restrict r,
                                     const float* __restrict t, float* __restrict bx,
                                     float* __restrict by, float* __restrict bz,
                                     std::uint8_t* __restrict valid, double* __restrict range2) {
  constexpr float kMax = std::numeric_limits<float>::max();
  for (std::size_t i = 0; i < n; ++i) {
    const bool keep = (static_cast<unsigned>((flags[i] & nan_mask) == 0) &
                       static_cast<unsigned>(std::abs(d[i]) <= kMax)) != 0;
    const float di = keep ? d[i] : kNan;
    const float x = di * rx[i], y = di * ry[i], z = di * rz[i];
    const float px = r[0] * x + r[3] * y + r[6] * z + t[0];
    const float py = r[1] * x + r[4] * y + r[7] * z + t[1];
    const float pz = r[2] * x + r[5] * y + r[8] * z + t[2];
    bx[i] = px;
    by[i] = py;
    bz[i] = pz;
    const unsigned finite = static_cast<unsigned>(std::abs(px) <= kMax) &
                            static_cast<unsigned>(std::abs(py) <= kMax) &
                            static_cast<unsigned>(std::abs(pz) <= kMax);
    valid[i] =
        static_cast<std::uint8_t>(static_cast<unsigned>((flags[i] & kRejectMask) == 0) & finite);
    const double dx = px, dy = py, dz = pz;
    range2[i] = dx * dx + dy * dy + dz * dz;
  }
}

// Floats of the strip for PanCells, with the error bounds (below).
struct FloatStrip {
  float f0, f1, f2, l0, l1, l2, u0, u1, u2;
  float max_az, max_tan, inv_res, cols, rows;
  float ec, er;  // bounds of |col - col_double| and |row - row_double|, cells
  float cut;     // branch-cut margin: |pl| <= cut * rho is too close to tell
};

// PanCells' loop. Error bounds, with e = 2^-24 and q = 1 + |t| >= |p| / rho (t = pu / rho the
// elevation's tangent): each of pf, pl, pu is within 4e|p| <= 4e q rho of its double value
// (axes rounded to float, two roundings of the sum); so the azimuth is within ~6e q of the
// double FastAtan2 of the same point, plus atan2F's own 1e-6 rad and 3e pi for rounding the
// strip's edge and the subtraction; t within ~16e q^2; col and row then gain 3e of their own
// size (the scaling). Each bound is doubled and taken at the largest q of a point inside the
// strip, q_max = 1 + max_tan + resolution + 1e-3, and the largest |col|, |row| there: constants
// (PanCells). A point with q > q_max is beyond the strip's rows by more than its error (up to
// |t| = 1e4, where that error is 16e q^2 < 1 % of t), so it is certainly out whatever its
// column. A point is certainly in when [col - ec, col + ec] and [row - er, row + er] lie inside
// the strip and inside one cell each, certainly out when either lies outside the strip;
// otherwise, and near the axis (rho < 2e-6, ExactCell's limit is 1e-6), beyond 1e18 m or
// |t| = 1e4, or near the azimuth's branch cut (pf < 0, |pl| <= 16e q_max rho, where the sign of
// pl, and with it az = +-pi, can differ between float and double), it is left to ExactCell.
// NaN fails every comparison: rechecked. The file is built without fused multiply-adds
// (src/pan/CMakeLists.txt), though one would only round less and the bounds would still hold.
// The AVX-512 clone: 8 % (SR-2) to 13 % (1 MP) faster assembly on Zen 4, measured when the clone
// still used fused multiply-adds; with 16 registers the AVX2 one spills.
TOFCAM_HOT_LOOP_WIDE void FastCells(std::size_t n, const FloatStrip& s, const float* __restrict x,
                                    const float* __restrict y, const float* __restrict z,
                                    std::int32_t* __restrict cell) {
  const FloatStrip k = s;
  const std::int32_t stride = static_cast<std::int32_t>(s.cols);
  for (std::size_t i = 0; i < n; ++i) {
    const float px = x[i], py = y[i], pz = z[i];
    const float pf = px * k.f0 + py * k.f1 + pz * k.f2;
    const float pl = px * k.l0 + py * k.l1 + pz * k.l2;
    const float pu = px * k.u0 + py * k.u1 + pz * k.u2;
    const float rho = std::sqrt(pf * pf + pl * pl);
    const float tan_el = pu / std::max(rho, 1e-6f);
    const float col = (k.max_az - internal::FastAtan2F(pl, pf)) * k.inv_res;
    const float row = (k.max_tan - tan_el) * k.inv_res;
    const float c_lo = col - k.ec, c_hi = col + k.ec, r_lo = row - k.er, r_hi = row + k.er;
    const bool inside = (c_lo >= 0.0f) & (c_hi < k.cols) & (r_lo >= 0.0f) & (r_hi < k.rows);
    const bool outside = (c_hi < 0.0f) | (c_lo >= k.cols) | (r_hi < 0.0f) | (r_lo >= k.rows);
    // Inside the strip the truncations are floors, and converting is defined.
    const auto c0 = static_cast<std::int32_t>(internal::SelF(inside, c_lo, 0.0f));
    const auto c1 = static_cast<std::int32_t>(internal::SelF(inside, c_hi, 0.0f));
    const auto r0 = static_cast<std::int32_t>(internal::SelF(inside, r_lo, 0.0f));
    const auto r1 = static_cast<std::int32_t>(internal::SelF(inside, r_hi, 0.0f));
    const bool plain = (rho >= 2e-6f) & (rho <= 1e18f) & (std::abs(tan_el) <= 1e4f) &
                       ((pf >= 0.0f) | (std::abs(pl) > k.cut * rho));
    const bool in = plain & inside & (c0 == c1) & (r0 == r1);
    const bool out = plain & outside;
    // in: the cell; certainly out: -1; otherwise -2.
    cell[i] =
        static_cast<std::int32_t>(in) * (r0 * stride + c0 + 2) - 2 + static_cast<std::int32_t>(out);
  }
}

#if defined(TOFCAM_AVX512_FORMS)
TOFCAM_AVX512_DIAGNOSTICS_BEGIN
// FastCells' constants, broadcast once per call of an AVX-512 form.
struct CellConsts {
  __m512 f0, f1, f2, l0, l1, l2, u0, u1, u2;
  __m512 max_az, max_tan, inv_res, cols, rows, ec, er, cut;
  __m512i stride;
};
TOFCAM_AVX512_INLINE CellConsts BroadcastStrip(const FloatStrip& k) {
  CellConsts c;
  c.f0 = _mm512_set1_ps(k.f0);
  c.f1 = _mm512_set1_ps(k.f1);
  c.f2 = _mm512_set1_ps(k.f2);
  c.l0 = _mm512_set1_ps(k.l0);
  c.l1 = _mm512_set1_ps(k.l1);
  c.l2 = _mm512_set1_ps(k.l2);
  c.u0 = _mm512_set1_ps(k.u0);
  c.u1 = _mm512_set1_ps(k.u1);
  c.u2 = _mm512_set1_ps(k.u2);
  c.max_az = _mm512_set1_ps(k.max_az);
  c.max_tan = _mm512_set1_ps(k.max_tan);
  c.inv_res = _mm512_set1_ps(k.inv_res);
  c.cols = _mm512_set1_ps(k.cols);
  c.rows = _mm512_set1_ps(k.rows);
  c.ec = _mm512_set1_ps(k.ec);
  c.er = _mm512_set1_ps(k.er);
  c.cut = _mm512_set1_ps(k.cut);
  c.stride = _mm512_set1_epi32(static_cast<std::int32_t>(k.cols));
  return c;
}

// FastCells for 16 points with AVX-512 intrinsics: the same geometry and tests, with fused
// multiply-adds (one rounding where FastCells has two, so every error bound above still holds
// and the cells after the recheck are the same) and the tests' logic in mask registers (GCC's
// clone of FastCells moved it to general registers and back, and spilled). Lanes not in `ok`
// get kNoCell; `undecided` receives the ok lanes left to ExactCell (kRecheckCell).
TOFCAM_AVX512_INLINE __m512i Cells16(const CellConsts& k, __m512 px, __m512 py, __m512 pz,
                                     __mmask16 ok, __mmask16& undecided) {
  const __m512 zero = _mm512_setzero_ps();
  const __m512 pf = _mm512_fmadd_ps(pz, k.f2, _mm512_fmadd_ps(py, k.f1, _mm512_mul_ps(px, k.f0)));
  const __m512 pl = _mm512_fmadd_ps(pz, k.l2, _mm512_fmadd_ps(py, k.l1, _mm512_mul_ps(px, k.l0)));
  const __m512 pu = _mm512_fmadd_ps(pz, k.u2, _mm512_fmadd_ps(py, k.u1, _mm512_mul_ps(px, k.u0)));
  const __m512 rho = _mm512_sqrt_ps(_mm512_fmadd_ps(pf, pf, _mm512_mul_ps(pl, pl)));
  const __m512 tan_el = _mm512_div_ps(pu, _mm512_max_ps(rho, _mm512_set1_ps(1e-6f)));
  const __m512 a = internal::FastAtan2F16(pl, pf);
  const __m512 ay = _mm512_abs_ps(pl);
  // The cell interval and its tests, as FastCells.
  const __m512 col = _mm512_mul_ps(_mm512_sub_ps(k.max_az, a), k.inv_res);
  const __m512 row = _mm512_mul_ps(_mm512_sub_ps(k.max_tan, tan_el), k.inv_res);
  const __m512 c_lo = _mm512_sub_ps(col, k.ec), c_hi = _mm512_add_ps(col, k.ec);
  const __m512 r_lo = _mm512_sub_ps(row, k.er), r_hi = _mm512_add_ps(row, k.er);
  __mmask16 inside = _mm512_cmp_ps_mask(c_lo, zero, _CMP_GE_OQ);
  inside = _mm512_mask_cmp_ps_mask(inside, c_hi, k.cols, _CMP_LT_OQ);
  inside = _mm512_mask_cmp_ps_mask(inside, r_lo, zero, _CMP_GE_OQ);
  inside = _mm512_mask_cmp_ps_mask(inside, r_hi, k.rows, _CMP_LT_OQ);
  const __mmask16 outside =
      _mm512_cmp_ps_mask(c_hi, zero, _CMP_LT_OQ) | _mm512_cmp_ps_mask(c_lo, k.cols, _CMP_GE_OQ) |
      _mm512_cmp_ps_mask(r_hi, zero, _CMP_LT_OQ) | _mm512_cmp_ps_mask(r_lo, k.rows, _CMP_GE_OQ);
  __mmask16 plain = _mm512_cmp_ps_mask(rho, _mm512_set1_ps(2e-6f), _CMP_GE_OQ);
  plain = _mm512_mask_cmp_ps_mask(plain, rho, _mm512_set1_ps(1e18f), _CMP_LE_OQ);
  plain = _mm512_mask_cmp_ps_mask(plain, _mm512_abs_ps(tan_el), _mm512_set1_ps(1e4f), _CMP_LE_OQ);
  plain &= _mm512_cmp_ps_mask(pf, zero, _CMP_GE_OQ) |
           _mm512_cmp_ps_mask(ay, _mm512_mul_ps(k.cut, rho), _CMP_GT_OQ);
  // Inside the strip the truncations are floors (other lanes' values are not used).
  const __m512i c0 = _mm512_cvttps_epi32(c_lo), c1 = _mm512_cvttps_epi32(c_hi);
  const __m512i r0 = _mm512_cvttps_epi32(r_lo), r1 = _mm512_cvttps_epi32(r_hi);
  __mmask16 in = plain & inside & ok;
  in = _mm512_mask_cmpeq_epi32_mask(in, c0, c1);
  in = _mm512_mask_cmpeq_epi32_mask(in, r0, r1);
  const __mmask16 out = (plain & outside) | static_cast<__mmask16>(~ok);
  undecided = static_cast<__mmask16>(ok & ~(in | out));
  // in: the cell; certainly out or not ok: kNoCell; otherwise kRecheckCell.
  const __m512i c = _mm512_mask_mov_epi32(_mm512_set1_epi32(internal::kRecheckCell), out,
                                          _mm512_set1_epi32(internal::kNoCell));
  return _mm512_mask_add_epi32(c, in, _mm512_mullo_epi32(r0, k.stride), c0);
}

// The lanes of a block of 16 that exist (the last block of n may be partial).
TOFCAM_AVX512_INLINE __mmask16 Lanes(std::size_t n, std::size_t i) {
  return n - i >= 16 ? __mmask16{0xffff} : static_cast<__mmask16>((1u << (n - i)) - 1u);
}

// FastCells and MaskInvalid in one pass (Cells16). Returns how many valid points are left to
// recheck.
TOFCAM_AVX512_TARGET std::uint32_t FastCellsAvx512(std::size_t n, const FloatStrip& strip,
                                                   const float* __restrict x,
                                                   const float* __restrict y,
                                                   const float* __restrict z,
                                                   const std::uint8_t* __restrict valid,
                                                   std::int32_t* __restrict cell) {
  const CellConsts k = BroadcastStrip(strip);
  std::uint32_t rechecks = 0;
  for (std::size_t i = 0; i < n; i += 16) {
    const __mmask16 lanes = Lanes(n, i);
    const __m128i vb = _mm_maskz_loadu_epi8(lanes, valid + i);
    __mmask16 undecided;
    const __m512i c =
        Cells16(k, _mm512_maskz_loadu_ps(lanes, x + i), _mm512_maskz_loadu_ps(lanes, y + i),
                _mm512_maskz_loadu_ps(lanes, z + i), _mm_test_epi8_mask(vb, vb), undecided);
    _mm512_mask_storeu_epi32(cell + i, lanes, c);
    rechecks += static_cast<std::uint32_t>(__builtin_popcount(undecided));
  }
  return rechecks;
}

// One base-frame coordinate, ((ra x + rb y) + rc z) + tr, in BasePoints' order.
TOFCAM_AVX512_INLINE __m512 RotateAxis(__m512 ra, __m512 rb, __m512 rc, __m512 tr, __m512 x,
                                       __m512 y, __m512 z) {
  return _mm512_add_ps(_mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(ra, x), _mm512_mul_ps(rb, y)),
                                     _mm512_mul_ps(rc, z)),
                       tr);
}

// Where BaseCellsAvx512 appends a chunk's points to the merged cloud: x, y, z, amplitude,
// intensity, ΔL and flags at their next free element (room for 16 past the last point), and
// whether every point is kept or only the valid ones.
struct AppendAt {
  float* channel[6];
  std::uint16_t* flags;
  bool keep_all;
};

// BasePoints, FastCells, MaskInvalid, SplatInputs and AppendPoints in one pass for one chunk:
// the base points (the same operations as BasePoints, in its order: the file is built without
// contraction, and these are separate multiplies and adds), their validity, for the splat each
// point's key (its range2 where it has or may have a cell, +inf where it certainly has none),
// distance and amplitude word, and cell (0 where none; kRecheckCell where ExactCell must
// decide), and the kept points appended to the cloud (compressed in a register, then a
// whole-vector store; the compress-to-memory form is microcoded and slow on Zen 4), so the
// cloud's stores overlap the arithmetic. Returns how many points are left to recheck; `kept`
// receives how many were appended.
TOFCAM_AVX512_TARGET std::uint32_t BaseCellsAvx512(
    std::size_t n, const float* __restrict d, const std::uint16_t* __restrict flags,
    std::uint16_t nan_mask, const float* __restrict a, const float* __restrict in,
    const float* __restrict dl, const float* __restrict rx, const float* __restrict ry,
    const float* __restrict rz, const float* __restrict r, const float* __restrict t,
    const FloatStrip& strip, float* __restrict bx, float* __restrict by, float* __restrict bz,
    double* __restrict key, std::uint64_t* __restrict da, std::int32_t* __restrict cell,
    const AppendAt& out, std::size_t& kept) {
  const CellConsts k = BroadcastStrip(strip);
  __m512 rot[9];
  for (int j = 0; j < 9; ++j) rot[j] = _mm512_set1_ps(r[j]);
  const __m512 t0 = _mm512_set1_ps(t[0]), t1 = _mm512_set1_ps(t[1]), t2 = _mm512_set1_ps(t[2]);
  const __m512 max = _mm512_set1_ps(std::numeric_limits<float>::max());
  const __m512 nan = _mm512_set1_ps(kNan);
  const __m256i nan_bits = _mm256_set1_epi16(static_cast<std::int16_t>(nan_mask));
  const __m256i reject_bits = _mm256_set1_epi16(static_cast<std::int16_t>(kRejectMask));
  const __m512d inf = _mm512_set1_pd(std::numeric_limits<double>::infinity());
  const __m512i interleave_lo =
      _mm512_setr_epi32(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
  const __m512i interleave_hi =
      _mm512_setr_epi32(8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31);
  std::uint32_t rechecks = 0;
  // The output pointers and count in locals: the stores may alias anything, so through `out` and
  // `kept` every store would reload them.
  float* __restrict const ox = out.channel[0];
  float* __restrict const oy = out.channel[1];
  float* __restrict const oz = out.channel[2];
  float* __restrict const oa = out.channel[3];
  float* __restrict const oi = out.channel[4];
  float* __restrict const odl = out.channel[5];
  std::uint16_t* __restrict const of = out.flags;
  const bool keep_all = out.keep_all;
  std::size_t appended = 0;
  for (std::size_t i = 0; i < n; i += 16) {
    const __mmask16 lanes = Lanes(n, i);
    const __m512 di = _mm512_maskz_loadu_ps(lanes, d + i);
    const __m256i f = _mm256_maskz_loadu_epi16(lanes, flags + i);
    const __mmask16 keep = _mm256_testn_epi16_mask(f, nan_bits) &
                           _mm512_cmp_ps_mask(_mm512_abs_ps(di), max, _CMP_LE_OQ);
    const __m512 dk = _mm512_mask_mov_ps(nan, keep, di);
    const __m512 x = _mm512_mul_ps(dk, _mm512_maskz_loadu_ps(lanes, rx + i));
    const __m512 y = _mm512_mul_ps(dk, _mm512_maskz_loadu_ps(lanes, ry + i));
    const __m512 z = _mm512_mul_ps(dk, _mm512_maskz_loadu_ps(lanes, rz + i));
    const __m512 px = RotateAxis(rot[0], rot[3], rot[6], t0, x, y, z);
    const __m512 py = RotateAxis(rot[1], rot[4], rot[7], t1, x, y, z);
    const __m512 pz = RotateAxis(rot[2], rot[5], rot[8], t2, x, y, z);
    _mm512_mask_storeu_ps(bx + i, lanes, px);
    _mm512_mask_storeu_ps(by + i, lanes, py);
    _mm512_mask_storeu_ps(bz + i, lanes, pz);
    __mmask16 ok = _mm256_testn_epi16_mask(f, reject_bits);
    ok = _mm512_mask_cmp_ps_mask(ok, _mm512_abs_ps(px), max, _CMP_LE_OQ);
    ok = _mm512_mask_cmp_ps_mask(ok, _mm512_abs_ps(py), max, _CMP_LE_OQ);
    ok = _mm512_mask_cmp_ps_mask(ok, _mm512_abs_ps(pz), max, _CMP_LE_OQ);
    ok &= lanes;
    // The kept points to the cloud.
    const __mmask16 append = keep_all ? lanes : ok;
    const __m512 av = _mm512_maskz_loadu_ps(lanes, a + i);
    _mm512_storeu_ps(ox + appended, _mm512_maskz_compress_ps(append, px));
    _mm512_storeu_ps(oy + appended, _mm512_maskz_compress_ps(append, py));
    _mm512_storeu_ps(oz + appended, _mm512_maskz_compress_ps(append, pz));
    _mm512_storeu_ps(oa + appended, _mm512_maskz_compress_ps(append, av));
    _mm512_storeu_ps(oi + appended,
                     _mm512_maskz_compress_ps(append, _mm512_maskz_loadu_ps(lanes, in + i)));
    _mm512_storeu_ps(odl + appended,
                     _mm512_maskz_compress_ps(append, _mm512_maskz_loadu_ps(lanes, dl + i)));
    _mm256_storeu_si256(
        reinterpret_cast<__m256i*>(of + appended),
        _mm512_cvtepi32_epi16(_mm512_maskz_compress_epi32(append, _mm512_cvtepu16_epi32(f))));
    appended += static_cast<std::size_t>(__builtin_popcount(append));
    __mmask16 undecided;
    const __m512i c = Cells16(k, px, py, pz, ok, undecided);
    // Lanes that may have a cell: in one (c >= 0) or undecided.
    const __mmask16 may = _mm512_cmpge_epi32_mask(c, _mm512_setzero_si512()) | undecided;
    _mm512_mask_storeu_epi32(cell + i, lanes, _mm512_maskz_mov_epi32(may, c));
    // range2 in double, as BasePoints: ((dx dx + dy dy) + dz dz), each square exact.
    for (int h = 0; h < 2; ++h) {
      const __mmask8 mh = static_cast<__mmask8>(may >> (8 * h));
      const __mmask8 lh = static_cast<__mmask8>(lanes >> (8 * h));
      const __m512d dx =
          _mm512_cvtps_pd(h == 0 ? _mm512_castps512_ps256(px) : _mm512_extractf32x8_ps(px, 1));
      const __m512d dy =
          _mm512_cvtps_pd(h == 0 ? _mm512_castps512_ps256(py) : _mm512_extractf32x8_ps(py, 1));
      const __m512d dz =
          _mm512_cvtps_pd(h == 0 ? _mm512_castps512_ps256(pz) : _mm512_extractf32x8_ps(pz, 1));
      const __m512d r2 = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy)),
                                       _mm512_mul_pd(dz, dz));
      _mm512_mask_storeu_pd(key + i + 8 * h, lh, _mm512_mask_mov_pd(inf, mh, r2));
    }
    // Distance and amplitude words: d in the low half, a in the high half.
    const __m512i db = _mm512_castps_si512(di);
    const __m512i ab = _mm512_castps_si512(av);
    _mm512_mask_storeu_epi64(da + i, static_cast<__mmask8>(lanes),
                             _mm512_permutex2var_epi32(db, interleave_lo, ab));
    _mm512_mask_storeu_epi64(da + i + 8, static_cast<__mmask8>(lanes >> 8),
                             _mm512_permutex2var_epi32(db, interleave_hi, ab));
    rechecks += static_cast<std::uint32_t>(__builtin_popcount(undecided));
  }
  kept = appended;
  return rechecks;
}
TOFCAM_AVX512_DIAGNOSTICS_END
#endif

// Invalid points get kNoCell; returns how many valid ones FastCells left to recheck. Apart from
// FastCells: with bytes in its loop GCC would unroll it four vectors deep and spill.
TOFCAM_HOT_LOOP std::uint32_t MaskInvalid(std::size_t n, const std::uint8_t* __restrict valid,
                                          std::int32_t* __restrict cell) {
  std::uint32_t rechecks = 0;  // 32 bits: GCC vectorises the count (n < 2^32 here)
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t c = valid[i] != 0 ? cell[i] : internal::kNoCell;
    cell[i] = c;
    rechecks += static_cast<std::uint32_t>(c == internal::kRecheckCell);
  }
  return rechecks;
}

// The first i0 + 64k (k >= 0) whose block of 64 cells holds kRecheckCell, or the first whose
// block would pass n. One lane reduction per block: GCC extracts the lanes one by one.
TOFCAM_HOT_LOOP std::size_t NextRecheckBlock(std::size_t i0, std::size_t n,
                                             const std::int32_t* __restrict cell) {
  using I8 = std::int32_t __attribute__((vector_size(32)));
  for (; i0 + 64 <= n; i0 += 64) {
    I8 hit = {};
    for (std::size_t j = 0; j < 64; j += 8) {
      I8 v;
      std::memcpy(&v, cell + i0 + j, sizeof v);
      hit |= v == internal::kRecheckCell;
    }
    std::uint64_t w[4];
    std::memcpy(w, &hit, sizeof w);
    if ((w[0] | w[1] | w[2] | w[3]) != 0) break;
  }
  return i0;
}

// The float strip of FastCells with its error bounds (see FastCells).
FloatStrip ToFloatStrip(const internal::PanStrip& s) {
  FloatStrip f{};
  f.f0 = static_cast<float>(s.forward[0]);
  f.f1 = static_cast<float>(s.forward[1]);
  f.f2 = static_cast<float>(s.forward[2]);
  f.l0 = static_cast<float>(s.left[0]);
  f.l1 = static_cast<float>(s.left[1]);
  f.l2 = static_cast<float>(s.left[2]);
  f.u0 = static_cast<float>(s.up[0]);
  f.u1 = static_cast<float>(s.up[1]);
  f.u2 = static_cast<float>(s.up[2]);
  f.max_az = static_cast<float>(s.max_azimuth_rad);
  f.max_tan = static_cast<float>(s.max_tan_elevation);
  f.inv_res = static_cast<float>(s.inv_resolution);
  f.cols = static_cast<float>(s.cols);
  f.rows = static_cast<float>(s.rows);
  constexpr double kE = 0x1p-24;
  const double inv_res = s.inv_resolution, max_tan = std::abs(s.max_tan_elevation);
  const double q_max = 1.0 + max_tan + 1.0 / inv_res + 1e-3;
  f.ec = static_cast<float>(
      2.0 * (inv_res * (1e-6 + kE * (6.0 * q_max + 10.0)) + 3.0 * kE * (s.cols + 1.0)));
  f.er = static_cast<float>(
      2.0 * (inv_res * kE * (16.0 * q_max * q_max + 2.0 * max_tan) + 3.0 * kE * (s.rows + 1.0)));
  f.cut = static_cast<float>(16.0 * kE * q_max);
  return f;
}

// Calls on_exact(i, ExactCell(point i)) for each of the `rechecks` points whose cell is
// kRecheckCell. A few per mille of the points (0.3 % at SR-2 on the default strip): blocks of 64
// cells without one are skipped with vector compares (NextRecheckBlock).
template <typename OnExact>
void RecheckCells(std::size_t n, const internal::PanStrip& s, const float* x, const float* y,
                  const float* z, std::size_t rechecks, const std::int32_t* cell,
                  OnExact on_exact) {
  using internal::ExactCell;
  using internal::kRecheckCell;
  std::size_t left = rechecks;
  std::size_t i0 = 0;
  while (left > 0) {
    i0 = NextRecheckBlock(i0, n, cell);
    if (i0 + 64 > n) break;
    for (std::size_t i = i0; i < i0 + 64; ++i) {
      if (cell[i] != kRecheckCell) continue;
      on_exact(i, ExactCell(s, x[i], y[i], z[i]));
      --left;
    }
    i0 += 64;
  }
  for (std::size_t i = i0; left > 0 && i < n; ++i) {
    if (cell[i] != kRecheckCell) continue;
    on_exact(i, ExactCell(s, x[i], y[i], z[i]));
    --left;
  }
}

// Reused buffers of MakePanView: per chunk, except the stand-ins for missing channels (per frame).
struct Scratch {
  std::vector<float> bx, by, bz;
  std::vector<double> range2, key;
  std::vector<std::uint64_t> da;
  std::vector<std::uint8_t> valid;
  std::vector<std::int32_t> cell;
  std::vector<float> nan_channel;         // a missing amplitude / intensity / ΔL
  std::vector<std::uint16_t> zero_flags;  // missing flags
  void Resize(std::size_t n) {
    for (auto* v : {&bx, &by, &bz}) v->resize(n);
    range2.resize(n);
    key.resize(n);
    da.resize(n);
    valid.resize(n);
    cell.resize(n);
  }
};

// kPack for the 8-bit mask m: the positions of m's set bits in ascending order (then zeros),
// i.e. the permutation that moves the kept lanes of a block of eight to its front, as 32-bit
// and 16-bit lane indices (loaded as they are: converting bytes costs GCC a dozen instructions),
// and the number of set bits (the baseline x86-64 has no popcount instruction).
struct PackTable {
  std::int32_t idx32[256][8];
  std::uint16_t idx16[256][8];
  std::uint8_t count[256];
};
constexpr PackTable MakePackTable() {
  PackTable t{};
  for (int m = 0; m < 256; ++m) {
    int k = 0;
    for (int b = 0; b < 8; ++b) {
      if ((m >> b) & 1) {
        t.idx32[m][k] = b;
        t.idx16[m][k] = static_cast<std::uint16_t>(b);
        ++k;
      }
    }
    t.count[m] = static_cast<std::uint8_t>(k);
  }
  return t;
}
constexpr PackTable kPack = MakePackTable();

// Packs the kept elements of one channel of T (float or 16-bit flags): block j of eight
// (masks[j], bit b = element b kept) has its lanes permuted by `table[masks[j]]` (lane indices
// of T's width) so that the kept ones come first, all eight are stored at the end, which then
// advances by the number kept (the rest is overwritten by the next block or lies beyond the
// cloud's final size). One channel per call keeps every pointer in a register.
template <typename T, typename Index>
[[gnu::always_inline]] inline void PackChannel(std::size_t blocks,
                                               const std::uint8_t* __restrict masks,
                                               const Index (*table)[8], const T* __restrict src,
                                               T* __restrict dst) {
  // typedef: GCC drops vector_size on a dependent type in a using-declaration.
  typedef T Vec __attribute__((vector_size(8 * sizeof(T))));
  typedef Index IndexVec __attribute__((vector_size(8 * sizeof(Index))));
  static_assert(sizeof(T) == sizeof(Index));
  for (std::size_t j = 0; j < blocks; ++j) {
    IndexVec idx;
    std::memcpy(&idx, table[masks[j]], sizeof idx);
    Vec v;
    std::memcpy(&v, src + 8 * j, sizeof v);
#if defined(__clang__)
    // clang has no variable-index shuffle builtin: lane by lane (it builds the fuzzers only).
    Vec packed;
    for (int l = 0; l < 8; ++l) packed[l] = v[idx[l]];
    v = packed;
#else
    v = __builtin_shuffle(v, idx);
#endif
    std::memcpy(dst, &v, sizeof v);
    dst += kPack.count[masks[j]];
  }
}

// The clones (clang cannot multiversion templates): the body above is inlined into each.
TOFCAM_HOT_LOOP void PackFloats(std::size_t blocks, const std::uint8_t* __restrict masks,
                                const float* __restrict src, float* __restrict dst) {
  PackChannel(blocks, masks, kPack.idx32, src, dst);
}
TOFCAM_HOT_LOOP void PackFlags(std::size_t blocks, const std::uint8_t* __restrict masks,
                               const std::uint16_t* __restrict src, std::uint16_t* __restrict dst) {
  PackChannel(blocks, masks, kPack.idx16, src, dst);
}

// Appends points [0, n) of one chunk (n <= kChunk) at `n_out` of the merged cloud, whose arrays
// have room for every point of every frame plus 8 (16 are reserved): the kept points (valid, or all
// with keep_all) in input order. valid[i] is 0 or 1 (BasePoints), which the 8-bit masks rely on.
// Returns the new end.
std::size_t AppendPoints(std::size_t n, bool keep_all, const float* bx, const float* by,
                         const float* bz, const float* a, const float* in, const float* dl,
                         const std::uint16_t* f, const std::uint8_t* valid, std::size_t n_out,
                         PointCloud& out) {
  float* o[6] = {out.x.data(),         out.y.data(),         out.z.data(),
                 out.amplitude.data(), out.intensity.data(), out.delta_l_m.data()};
  const float* src[6] = {bx, by, bz, a, in, dl};
  auto* of = reinterpret_cast<std::uint16_t*>(out.flags.data());
  if (keep_all) {
    for (int k = 0; k < 6; ++k) std::memcpy(o[k] + n_out, src[k], n * sizeof(float));
    std::memcpy(of + n_out, f, n * sizeof(std::uint16_t));
    return n_out + n;
  }
  const std::size_t blocks = n / 8;
  std::uint8_t masks[kChunk / 8];
  std::size_t kept = 0;
  for (std::size_t j = 0; j < blocks; ++j) {
    std::uint64_t word;  // eight 0/1 bytes -> an 8-bit mask (bit b = byte b)
    std::memcpy(&word, valid + 8 * j, sizeof word);
    masks[j] = static_cast<std::uint8_t>((word * 0x0102040810204080ull) >> 56);
    kept += kPack.count[masks[j]];
  }
  for (int k = 0; k < 6; ++k) PackFloats(blocks, masks, src[k], o[k] + n_out);
  PackFlags(blocks, masks, f, of + n_out);
  n_out += kept;
  for (std::size_t i = 8 * blocks; i < n; ++i) {
    for (int k = 0; k < 6; ++k) o[k][n_out] = src[k][i];
    of[n_out] = f[i];
    n_out += valid[i];
  }
  return n_out;
}

// A panorama cell while the frames are splatted: the key of the nearest point so far (its
// squared distance from the rotation centre; +inf when empty) and its distance and amplitude
// packed into one word (PackDA).
struct alignas(16) ZCell {
  double range2;
  std::uint64_t distance_amplitude;
};
[[gnu::always_inline]] inline std::uint64_t PackDA(float d, float a) {
  return std::bit_cast<std::uint32_t>(d) | (std::uint64_t{std::bit_cast<std::uint32_t>(a)} << 32);
}
static_assert(sizeof(ZCell) == 16);

// The splat's inputs per point: its key (range2 where it has a cell, else +inf, which never
// wins), a cell index that is always valid (0 for points without one) and its distance and
// amplitude as one 8-byte word (the second half of its ZCell).
TOFCAM_HOT_LOOP_WIDE void SplatInputs(std::size_t n, std::int32_t* __restrict cell,
                                      const double* __restrict range2, const float* __restrict d,
                                      const float* __restrict a, double* __restrict key,
                                      std::uint64_t* __restrict da) {
  for (std::size_t i = 0; i < n; ++i) {
    const bool inside = cell[i] >= 0;
    key[i] = inside ? range2[i] : std::numeric_limits<double>::infinity();
    cell[i] = inside ? cell[i] : 0;
    da[i] = PackDA(d[i], a[i]);
  }
}

// Splat: the point nearest to the rotation centre wins its cell (the first of equals). Two
// forms with the same result. Coarse pixels (fewer than kBranchFreePointsPerCell points of a frame
// per cell of the strip, e.g. SR-2 and VGA frames on the default 0.5° strip): every point
// rewrites its 16-byte cell branch-free, since neighbouring points compete for cells in an
// order no branch predictor learns (points without a cell rewrite cell 0 with its own value:
// their key +inf never wins). Fine pixels (more points per cell): runs of points hit one cell
// and rarely win it, so a branch predicts well, while rewriting the cell every time would chain
// each point on the previous one's store.
// Where the two forms trade, in points of one frame per cell: pan_bench's
// BM_MakePanViewIntoStrip (VGA frames on strips of 0.2° to 2°, Zen 4) measured the branch-free
// form 25 % faster at 1 point per cell, 7 % at 6, level at 12-13 and 8-25 % slower at 25-100.
constexpr std::size_t kBranchFreePointsPerCell = 12;

void SplatBranchy(std::size_t n, const std::int32_t* __restrict cell, const double* __restrict key,
                  const std::uint64_t* __restrict da, ZCell* __restrict zb) {
  for (std::size_t i = 0; i < n; ++i) {
    ZCell& z = zb[cell[i]];
    if (key[i] < z.range2) z = ZCell{key[i], da[i]};
  }
}

using D2 = double __attribute__((vector_size(16)));
using L2 = std::int64_t __attribute__((vector_size(16)));

TOFCAM_HOT_LOOP_WIDE void Splat(std::size_t n, const std::int32_t* __restrict cell,
                                const double* __restrict key, const std::uint64_t* __restrict da,
                                ZCell* __restrict zb) {
  for (std::size_t i = 0; i < n; ++i) {
    ZCell* __restrict z = zb + cell[i];
    D2 old;
    std::memcpy(&old, z, sizeof old);
    // The candidate record in registers (through memory its two halves would be stored
    // separately and reloaded as one, which store forwarding cannot serve); lane 1 only carries
    // bits, no arithmetic touches it.
    const D2 next = {key[i], std::bit_cast<double>(da[i])};
    const D2 k = {key[i], key[i]}, o = {old[0], old[0]};
    const L2 nearer = k < o;
    const D2 merged =
        std::bit_cast<D2>((std::bit_cast<L2>(next) & nearer) | (std::bit_cast<L2>(old) & ~nearer));
    std::memcpy(z, &merged, sizeof merged);
  }
}

// Every cell empty: key +inf, distance and amplitude NaN. Each cell a copy of one constant
// record, so that the loop is a vector store (an assign of ZCell records compiled to two scalar
// stores each).
TOFCAM_HOT_LOOP void ClearZBuffer(std::size_t n, ZCell* __restrict zb) {
  const ZCell empty{std::numeric_limits<double>::infinity(), PackDA(kNan, kNan)};
  for (std::size_t i = 0; i < n; ++i) std::memcpy(zb + i, &empty, sizeof empty);
}

// The panorama's distance and amplitude from the cells' words.
TOFCAM_HOT_LOOP void UnpackZBuffer(std::size_t n, const ZCell* __restrict zb,
                                   float* __restrict distance, float* __restrict amplitude) {
  for (std::size_t c = 0; c < n; ++c) {
    const std::uint64_t da = zb[c].distance_amplitude;
    distance[c] = std::bit_cast<float>(static_cast<std::uint32_t>(da));
    amplitude[c] = std::bit_cast<float>(static_cast<std::uint32_t>(da >> 32));
  }
}

}  // namespace

void PanViewOptions::Validate() const {
  const Eigen::Vector3d a = pan_unit.axis;
  if (!a.allFinite() || a.norm() < 1e-9 || !pan_unit.camera_offset_m.allFinite()) {
    throw Error(ErrorCode::kInvalidArgument, "pan view: pan_unit axis must be finite and non-zero");
  }
  // The azimuth origin is the base z axis projected perpendicular to the axis.
  if (std::abs(a.normalized().z()) > 0.999) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: pan_unit axis must not be (nearly) the optical axis z");
  }
  if (!(resolution_deg >= 0.01 && resolution_deg <= 10.0)) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "pan view: resolution_deg = " + std::to_string(resolution_deg) + " is outside [0.01, 10]");
  }
  if (!(min_azimuth_deg >= -180.0 && max_azimuth_deg <= 180.0 &&
        max_azimuth_deg > min_azimuth_deg)) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: azimuth range [" + std::to_string(min_azimuth_deg) + ", " +
                    std::to_string(max_azimuth_deg) + "] deg must be non-empty within ±180");
  }
  if (!(max_elevation_deg > 0.0 && max_elevation_deg <= 80.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: max_elevation_deg = " + std::to_string(max_elevation_deg) +
                    " is outside (0, 80]");
  }
  // The strip's size as MakePanViewInto computes it. At least one cell (every point without a
  // cell is splatted into cell 0, with a key that never wins); at most kMaxPanoramaCells (the
  // cells are indexed in 32 bits, and each costs 27 bytes while the view is built).
  const double cols = std::ceil((max_azimuth_deg - min_azimuth_deg) / resolution_deg - 1e-9);
  const double rows =
      std::ceil(2.0 * std::tan(max_elevation_deg * kDeg) / (resolution_deg * kDeg) - 1e-9);
  if (!(cols >= 1.0 && rows >= 1.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: the strip has no cells (" + std::to_string(cols) + " columns x " +
                    std::to_string(rows) +
                    " rows): widen the azimuth or elevation range or choose a finer "
                    "resolution_deg");
  }
  const double cells = cols * rows;
  if (cells > kMaxPanoramaCells) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: the strip would have " + std::to_string(cells / 1e6) +
                    " million cells (at most " + std::to_string(kMaxPanoramaCells / 1e6) +
                    " million): choose a coarser resolution_deg or a narrower strip");
  }
  color.Validate();
}

double PanView::RowElevationRad(int row) const noexcept {
  return std::atan(max_tan_elevation - (row + 0.5) * resolution_rad);
}

PointCloud TransformPointCloud(const PointCloud& cloud, const Eigen::Isometry3d& t) {
  cloud.Validate();
  PointCloud out = cloud;
  const Eigen::Matrix3f r = t.linear().cast<float>();
  const Eigen::Vector3f o = t.translation().cast<float>();
  for (std::size_t i = 0; i < out.size(); ++i) {
    const Eigen::Vector3f p = r * Eigen::Vector3f(cloud.x[i], cloud.y[i], cloud.z[i]) + o;
    out.x[i] = p.x();
    out.y[i] = p.y();
    out.z[i] = p.z();
  }
  return out;
}

PanView MakePanView(std::span<const MetricFrame> frames, const RayTable& rays,
                    const PanViewOptions& o) {
  PanView view;
  MakePanViewInto(frames, rays, o, view);
  return view;
}

void MakePanViewInto(std::span<const MetricFrame> frames, const RayTable& rays,
                     const PanViewOptions& o, PanView& view) {
  o.Validate();
  if (frames.empty()) throw Error(ErrorCode::kInvalidArgument, "pan view: no frames");
  // Every check before `view` is touched.
  for (std::size_t k = 0; k < frames.size(); ++k) {
    kernels::CheckCloudInputs(frames[k], rays);
    if (!std::isfinite(frames[k].info.pan_angle_rad)) {
      throw Error(ErrorCode::kInvalidArgument,
                  "pan view: frame " + std::to_string(k) + " has a non-finite pan angle");
    }
  }
  view.resolution_rad = o.resolution_deg * kDeg;
  view.max_azimuth_rad = o.max_azimuth_deg * kDeg;
  view.max_tan_elevation = std::tan(o.max_elevation_deg * kDeg);
  const int cols = static_cast<int>(
      std::ceil((o.max_azimuth_deg - o.min_azimuth_deg) / o.resolution_deg - 1e-9));
  const int rows =
      static_cast<int>(std::ceil(2.0 * view.max_tan_elevation / view.resolution_rad - 1e-9));
  const std::size_t n_cells = static_cast<std::size_t>(cols) * static_cast<std::size_t>(rows);
  // Reused storage: the previous view's images and a per-thread z-buffer (a fresh 100 KB+ image
  // per call is a fresh mapping from the kernel, page-faulted in on every call).
  for (Image<float>* image : {&view.panorama_distance_m, &view.panorama_amplitude}) {
    if (!image->SameSize(cols, rows)) *image = Image<float>(cols, rows);
  }
  thread_local std::vector<ZCell> zbuffer;
  zbuffer.resize(n_cells);
  ClearZBuffer(n_cells, zbuffer.data());
  view.frame_offsets.clear();
  view.camera_to_base.clear();

  const Eigen::Vector3d up = o.pan_unit.axis.normalized();
  const Eigen::Vector3d z(0.0, 0.0, 1.0);
  const Eigen::Vector3d forward = (z - z.dot(up) * up).normalized();
  const Eigen::Vector3d left = up.cross(forward);
  internal::PanStrip strip{};
  for (int i = 0; i < 3; ++i) {
    strip.forward[i] = forward[i];
    strip.left[i] = left[i];
    strip.up[i] = up[i];
  }
  strip.max_azimuth_rad = view.max_azimuth_rad;
  strip.max_tan_elevation = view.max_tan_elevation;
  strip.inv_resolution = 1.0 / view.resolution_rad;
  strip.cols = cols;
  strip.rows = rows;
  view.cloud.height = 1;
  view.frame_offsets.push_back(0);

  // The merged cloud is written in place (room for every point of every frame, plus a block of
  // 16 for the appends' whole-vector stores), then trimmed.
  std::size_t capacity = 16;
  for (const MetricFrame& frame : frames) capacity += frame.radial_distance_m.size();
  PointCloud& out = view.cloud;
  for (auto* v : {&out.x, &out.y, &out.z, &out.amplitude, &out.intensity, &out.delta_l_m}) {
    v->resize(capacity);
  }
  out.flags.resize(capacity);
  std::size_t n_out = 0;
  thread_local Scratch sc;
  // The AVX-512 form fuses BasePoints, PanCells' float loop, SplatInputs and AppendPoints
  // (BaseCellsAvx512).
#if defined(TOFCAM_AVX512_FORMS)
  const bool fused = internal::UseAvx512Forms();
  const FloatStrip float_strip = ToFloatStrip(strip);
#else
  constexpr bool fused = false;
#endif
  static_assert(sizeof(PixelFlags) == sizeof(std::uint16_t));
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const MetricFrame& frame = frames[k];
    const Eigen::Isometry3d pose = o.pan_unit.CameraToBase(frame.info.pan_angle_rad);
    view.camera_to_base.push_back(pose);
    const Eigen::Matrix3f rot = pose.linear().cast<float>();  // column-major
    const Eigen::Vector3f tr = pose.translation().cast<float>();
    const std::size_t n = frame.radial_distance_m.size();
    sc.Resize(std::min(n, kChunk));
    // Missing channels: NaN values, clear flags (as MakePointCloud).
    auto channel = [&](const Image<float>& c) {
      if (!c.empty()) return c.data();
      if (sc.nan_channel.size() < n) sc.nan_channel.assign(n, kNan);
      return static_cast<const float*>(sc.nan_channel.data());
    };
    const float* amplitude = channel(frame.amplitude);
    const float* intensity = channel(frame.intensity);
    const float* delta_l = channel(frame.delta_l_m);
    const std::uint16_t* flags = nullptr;
    if (frame.flags.empty()) {
      if (sc.zero_flags.size() < n) sc.zero_flags.assign(n, 0);
      flags = sc.zero_flags.data();
    } else {
      flags = reinterpret_cast<const std::uint16_t*>(frame.flags.data());
    }
    // Chunks of kChunk points through every pass, so that the scratch arrays stay in the core's
    // cache (at 1 MP a whole frame's would go through memory five times).
    const bool coarse = n < kBranchFreePointsPerCell * n_cells;
    const float* d = frame.radial_distance_m.data();
    for (std::size_t b = 0; b < n; b += kChunk) {
      const std::size_t m = std::min(kChunk, n - b);
      if (fused) {
#if defined(TOFCAM_AVX512_FORMS)
        // Base points, cells, the splat's inputs and the cloud in one pass; the undecided cells
        // after.
        const AppendAt at{{out.x.data() + n_out, out.y.data() + n_out, out.z.data() + n_out,
                           out.amplitude.data() + n_out, out.intensity.data() + n_out,
                           out.delta_l_m.data() + n_out},
                          reinterpret_cast<std::uint16_t*>(out.flags.data()) + n_out,
                          !o.only_valid};
        std::size_t kept = 0;
        const std::uint32_t rechecks =
            BaseCellsAvx512(m, d + b, flags + b, o.cloud.nan_mask, amplitude + b, intensity + b,
                            delta_l + b, rays.x.data() + b, rays.y.data() + b, rays.z.data() + b,
                            rot.data(), tr.data(), float_strip, sc.bx.data(), sc.by.data(),
                            sc.bz.data(), sc.key.data(), sc.da.data(), sc.cell.data(), at, kept);
        n_out += kept;
        std::int32_t* cell = sc.cell.data();
        double* key = sc.key.data();
        RecheckCells(m, strip, sc.bx.data(), sc.by.data(), sc.bz.data(), rechecks, cell,
                     [cell, key](std::size_t i, std::int32_t c) {
                       cell[i] = c >= 0 ? c : 0;
                       if (c < 0) key[i] = std::numeric_limits<double>::infinity();
                     });
#endif
      } else {
        BasePoints(m, d + b, flags + b, o.cloud.nan_mask, rays.x.data() + b, rays.y.data() + b,
                   rays.z.data() + b, rot.data(), tr.data(), sc.bx.data(), sc.by.data(),
                   sc.bz.data(), sc.valid.data(), sc.range2.data());
        internal::PanCells(m, strip, sc.bx.data(), sc.by.data(), sc.bz.data(), sc.valid.data(),
                           sc.cell.data());
        SplatInputs(m, sc.cell.data(), sc.range2.data(), d + b, amplitude + b, sc.key.data(),
                    sc.da.data());
        n_out =
            AppendPoints(m, !o.only_valid, sc.bx.data(), sc.by.data(), sc.bz.data(), amplitude + b,
                         intensity + b, delta_l + b, flags + b, sc.valid.data(), n_out, out);
      }

      // The z-buffered splat.
      (coarse ? Splat : SplatBranchy)(m, sc.cell.data(), sc.key.data(), sc.da.data(),
                                      zbuffer.data());
    }
    view.frame_offsets.push_back(n_out);
  }
  for (auto* v : {&out.x, &out.y, &out.z, &out.amplitude, &out.intensity, &out.delta_l_m}) {
    v->resize(n_out);
  }
  out.flags.resize(n_out);
  view.cloud.width = static_cast<int>(view.cloud.x.size());
  if (view.cloud.width == 0) view.cloud.height = 0;
  float* pano_d = view.panorama_distance_m.data();
  float* pano_a = view.panorama_amplitude.data();
  UnpackZBuffer(n_cells, zbuffer.data(), pano_d, pano_a);

  const double f_hz = frames[0].info.modulation_frequency_hz;
  const double far_default = (std::isfinite(f_hz) && f_hz > 0.0) ? UnambiguousRangeM(f_hz) : 0.0;
  FalseColorImageInto(view.panorama_distance_m, Image<PixelFlags>(), view.panorama_amplitude,
                      far_default, o.color, view.panorama);
}

namespace internal {

std::size_t PanCells(std::size_t n, const PanStrip& s, const float* x, const float* y,
                     const float* z, const std::uint8_t* valid, std::int32_t* cell) {
  const FloatStrip f = ToFloatStrip(s);
  std::size_t rechecks = 0;
  // MakePanViewInto's AVX-512 form calls Cells16 itself (BaseCellsAvx512) and PanCells only
  // without it; this branch runs Cells16 on PanCellsTest's points (borders, branch cut, axis).
#if defined(TOFCAM_AVX512_FORMS)
  if (UseAvx512Forms()) {
    rechecks = FastCellsAvx512(n, f, x, y, z, valid, cell);
  } else
#endif
  {
    FastCells(n, f, x, y, z, cell);
    rechecks = MaskInvalid(n, valid, cell);
  }
  RecheckCells(n, s, x, y, z, rechecks, cell,
               [cell](std::size_t i, std::int32_t c) { cell[i] = c; });
  return rechecks;
}

}  // namespace internal

}  // namespace tofcam

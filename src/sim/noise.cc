#include "noise.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "../core/avx512_forms.h"
#include "hot_loop.h"
#include "rng.h"

#if defined(TOFCAM_AVX512_FORMS)
#include <immintrin.h>
#endif

namespace tofcam::sim::internal {

const NormalTable& GetNormalTable() {
  static const NormalTable table;
  return table;
}

// The loop below takes __restrict pointers and is kept out of line (see hot_loop.h).
// Per pixel of a row: the standard deviation of the Gaussian shot noise of each tap and
// the ground-truth sigma L sqrt(B + s^2) / (2 sqrt(2) pi A) (0 without signal), vectorised.
TOFCAM_SIM_LOOP void NoiseScales(int n, double read_var, double sigma_scale,
                                 const double* __restrict mu0, const double* __restrict mu1,
                                 const double* __restrict mu2, const double* __restrict mu3,
                                 const double* __restrict a_mean, const double* __restrict b_mean,
                                 float* __restrict sd0, float* __restrict sd1,
                                 float* __restrict sd2, float* __restrict sd3,
                                 float* __restrict sigma, float* __restrict noise) {
  for (int c = 0; c < n; ++c) {
    // Single precision: the normal deviates these scale are floats and the truth sigma is stored
    // as one; packed float square roots are several times faster than double ones. Only means of
    // at least kPoissonGaussMean use them, so a negative mean (NaN here) never does; clamping it
    // would let GCC branch on the constant sqrt(0) and keep the loop scalar.
    sd0[c] = std::sqrt(static_cast<float>(mu0[c]));
    sd1[c] = std::sqrt(static_cast<float>(mu1[c]));
    sd2[c] = std::sqrt(static_cast<float>(mu2[c]));
    sd3[c] = std::sqrt(static_cast<float>(mu3[c]));
    noise[c] = static_cast<float>(b_mean[c] + read_var);
    // 0 where there is no signal, selected with a bit mask: GCC may turn a select (or a product
    // with the condition) into a branch around the division, which keeps the loop scalar.
    const float s = static_cast<float>(sigma_scale / (a_mean[c] + 1e-300)) * std::sqrt(noise[c]);
    const std::uint32_t lit = 0u - static_cast<std::uint32_t>(a_mean[c] > 0);
    sigma[c] = std::bit_cast<float>(std::bit_cast<std::uint32_t>(s) & lit);
  }
}

namespace {

// One tap's draws: shot noise (Rng::Poisson with sqrt(mean) precomputed, vectorised, in the
// Gaussian regime), then read noise. The one definition NoisyTaps and the AVX-512 form's rare
// lanes (ScalarLanes) share.
inline float TapDraws(Rng& rng, double mu, float sd, bool shot_noise, double read_sigma) {
  double v = mu;
  if (shot_noise) v = v >= kPoissonGaussMean ? v + sd * rng.Normal() : rng.Poisson(v);
  if (read_sigma > 0) v += read_sigma * rng.Normal();
  return static_cast<float>(v);
}

}  // namespace

void NoisyTaps(int n, std::uint64_t seed, bool shot_noise, double read_sigma,
               const double* const mu[4], const float* const sd[4], float* const taps[4]) {
  Rng rng(seed);
  for (int c = 0; c < n; ++c) {
    for (int k = 0; k < 4; ++k) {
      taps[k][c] = TapDraws(rng, mu[k][c], shot_noise ? sd[k][c] : 0.f, shot_noise, read_sigma);
    }
  }
}

namespace {

#if defined(TOFCAM_AVX512_FORMS)
// The scalar helpers of the AVX-512 form (compiled for the baseline; only that form calls them).

// The eight streams of NoisyTaps8 as a state table: word w of lane j's xoshiro state is
// words[w][j] (the layout of four 8-lane vectors).
using LaneStates = std::uint64_t[4][8];

Rng LaneRng(const LaneStates& words, int j) {
  return Rng::FromState({words[0][j], words[1][j], words[2][j], words[3][j]});
}

void StoreLane(const Rng& rng, int j, LaneStates& words) {
  for (int w = 0; w < 4; ++w) words[w][j] = rng.state()[w];
}

// A whole tap step (TapDraws) of the eight lanes one by one: the AVX-512 form's path for a step
// in which some lane's mean is in the exact Poisson regime. Out of line and compiled for the
// baseline like NoisyTaps, so its arithmetic is NoisyTaps' by construction.
[[gnu::noinline]] void ScalarLanes(LaneStates& words, const double* mu, const float* sd,
                                   bool shot_noise, double read_sigma, float* out) {
  for (int j = 0; j < 8; ++j) {
    Rng rng = LaneRng(words, j);
    out[j] = TapDraws(rng, mu[j], shot_noise ? sd[j] : 0.f, shot_noise, read_sigma);
    StoreLane(rng, j, words);
  }
}

// Rng::Tail for the lanes in `lanes` whose draw fell in an outermost table cell (about one draw
// in 2000): each continues its own stream. Out of line for the same reason as ScalarLanes.
[[gnu::noinline]] void TailLanes(LaneStates& words, unsigned lanes, const std::uint64_t* cells,
                                 float* values) {
  for (int j = 0; j < 8; ++j) {
    if (((lanes >> j) & 1u) == 0) continue;
    Rng rng = LaneRng(words, j);
    values[j] = rng.Tail(static_cast<int>(cells[j]));
    StoreLane(rng, j, words);
  }
}

TOFCAM_AVX512_DIAGNOSTICS_BEGIN

struct Streams {
  __m512i s0, s1, s2, s3;
};

TOFCAM_AVX512_INLINE void Spill(const Streams& v, LaneStates& words) {
  _mm512_storeu_si512(words[0], v.s0);
  _mm512_storeu_si512(words[1], v.s1);
  _mm512_storeu_si512(words[2], v.s2);
  _mm512_storeu_si512(words[3], v.s3);
}

TOFCAM_AVX512_INLINE Streams Reload(const LaneStates& words) {
  return {_mm512_loadu_si512(words[0]), _mm512_loadu_si512(words[1]), _mm512_loadu_si512(words[2]),
          _mm512_loadu_si512(words[3])};
}

// Rng::Next in eight lanes.
TOFCAM_AVX512_INLINE __m512i Next8(Streams& v) {
  const __m512i result = _mm512_add_epi64(_mm512_rol_epi64(_mm512_add_epi64(v.s0, v.s3), 23), v.s0);
  const __m512i t = _mm512_slli_epi64(v.s1, 17);
  v.s2 = _mm512_xor_si512(v.s2, v.s0);
  v.s3 = _mm512_xor_si512(v.s3, v.s1);
  v.s1 = _mm512_xor_si512(v.s1, v.s2);
  v.s0 = _mm512_xor_si512(v.s0, v.s3);
  v.s2 = _mm512_xor_si512(v.s2, t);
  v.s3 = _mm512_rol_epi64(v.s3, 45);
  return result;
}

// Rng::Normal in eight lanes: the table cell and its right neighbour in one 64-bit load, the
// fraction converted exactly as the scalar code does (a 32-bit integer to float, nearest), then
// the same float subtract, multiply and add (the file is built with -ffp-contract=off). Lanes in
// an outermost cell go to TailLanes.
TOFCAM_AVX512_INLINE __m256 Normal8(Streams& v, const float* table, LaneStates& words) {
  const __m512i r = Next8(v);
  const __m512i cell = _mm512_srli_epi64(r, 52);
  // The table pairs by eight scalar 64-bit loads: measured slightly faster than the hardware
  // gather on a Zen 5 (BM_NoisyTaps/1, three alternated pairs: 32-34 against 35-36 us).
  alignas(64) std::uint64_t at[8];
  alignas(64) std::uint64_t pairs[8];
  _mm512_store_si512(at, cell);
  for (int j = 0; j < 8; ++j) std::memcpy(&pairs[j], table + at[j], sizeof pairs[j]);
  const __m512i pair = _mm512_load_si512(pairs);
  const __m256 lo = _mm256_castsi256_ps(_mm512_cvtepi64_epi32(pair));
  const __m256 hi = _mm256_castsi256_ps(_mm512_cvtepi64_epi32(_mm512_srli_epi64(pair, 32)));
  const __m512i bits = _mm512_and_si512(_mm512_srli_epi64(r, 20), _mm512_set1_epi64(0xFFFFFFFF));
  const __m256 frac = _mm256_mul_ps(_mm512_cvtepu64_ps(bits), _mm256_set1_ps(0x1.0p-32f));
  __m256 n = _mm256_add_ps(lo, _mm256_mul_ps(frac, _mm256_sub_ps(hi, lo)));
  const __mmask8 tail = _mm512_cmpeq_epi64_mask(cell, _mm512_setzero_si512()) |
                        _mm512_cmpeq_epi64_mask(cell, _mm512_set1_epi64(NormalTable::kCells - 1));
  if (tail != 0) [[unlikely]] {
    alignas(32) float values[8];
    _mm256_store_ps(values, n);
    Spill(v, words);
    TailLanes(words, tail, at, values);
    v = Reload(words);
    n = _mm256_load_ps(values);
  }
  return n;
}

// r[i][j] -> r[j][i] for an 8 x 8 matrix of rows r[0..7] (three rounds of two-source permutes:
// 1 x 1, 2 x 2 and 4 x 4 blocks), for 64-bit lanes (doubles) and 32-bit lanes (floats).
#define TOFCAM_DEFINE_TRANSPOSE8(name, Vec, Index, set_index, permute) \
  TOFCAM_AVX512_INLINE void name(Vec r[8]) {                           \
    const Index i1lo = set_index(0, 8, 2, 10, 4, 12, 6, 14);           \
    const Index i1hi = set_index(1, 9, 3, 11, 5, 13, 7, 15);           \
    const Index i2lo = set_index(0, 1, 8, 9, 4, 5, 12, 13);            \
    const Index i2hi = set_index(2, 3, 10, 11, 6, 7, 14, 15);          \
    const Index i3lo = set_index(0, 1, 2, 3, 8, 9, 10, 11);            \
    const Index i3hi = set_index(4, 5, 6, 7, 12, 13, 14, 15);          \
    Vec a[8], b[8];                                                    \
    for (int p = 0; p < 8; p += 2) {                                   \
      a[p] = permute(r[p], i1lo, r[p + 1]);                            \
      a[p + 1] = permute(r[p], i1hi, r[p + 1]);                        \
    }                                                                  \
    for (int p = 0; p < 8; p += 4) {                                   \
      b[p] = permute(a[p], i2lo, a[p + 2]);                            \
      b[p + 2] = permute(a[p], i2hi, a[p + 2]);                        \
      b[p + 1] = permute(a[p + 1], i2lo, a[p + 3]);                    \
      b[p + 3] = permute(a[p + 1], i2hi, a[p + 3]);                    \
    }                                                                  \
    for (int p = 0; p < 4; ++p) {                                      \
      r[p] = permute(b[p], i3lo, b[p + 4]);                            \
      r[p + 4] = permute(b[p], i3hi, b[p + 4]);                        \
    }                                                                  \
  }
TOFCAM_DEFINE_TRANSPOSE8(Transpose8Pd, __m512d, __m512i, _mm512_setr_epi64, _mm512_permutex2var_pd)
TOFCAM_DEFINE_TRANSPOSE8(Transpose8Ps, __m256, __m256i, _mm256_setr_epi32, _mm256_permutex2var_ps)
#undef TOFCAM_DEFINE_TRANSPOSE8

// NoisyTaps for eight rows at once, one row's stream per 64-bit lane: the same draws in the same
// order per row, so the same values bit for bit. Means and sigmas are transposed in blocks of
// eight columns (column-major scratch), the taps transposed back.
TOFCAM_AVX512_TARGET void NoisyTaps8(int n, std::size_t stride, const std::uint64_t* seeds,
                                     bool shot_noise, double read_sigma, const double* const mu[4],
                                     const float* const sd[4], float* const taps[][4]) {
  alignas(64) LaneStates words;
  for (int j = 0; j < 8; ++j) StoreLane(Rng(seeds[j]), j, words);
  Streams v = Reload(words);
  const float* table = GetNormalTable().data();
  const __m512d gauss_from = _mm512_set1_pd(kPoissonGaussMean);
  const __m512d vread = _mm512_set1_pd(read_sigma);
  const bool read = read_sigma > 0;
  alignas(64) double mu_t[4][8][8];
  alignas(64) float sd_t[4][8][8];
  alignas(64) float out_t[4][8][8] = {};
  for (int c0 = 0; c0 < n; c0 += 8) {
    const int cols = std::min(8, n - c0);
    const auto in = static_cast<__mmask8>((1u << cols) - 1u);
    for (int k = 0; k < 4; ++k) {
      __m512d r[8];
      for (int j = 0; j < 8; ++j) r[j] = _mm512_maskz_loadu_pd(in, mu[k] + j * stride + c0);
      Transpose8Pd(r);
      for (int c = 0; c < 8; ++c) _mm512_store_pd(mu_t[k][c], r[c]);
      if (!shot_noise) continue;
      __m256 q[8];
      for (int j = 0; j < 8; ++j) q[j] = _mm256_maskz_loadu_ps(in, sd[k] + j * stride + c0);
      Transpose8Ps(q);
      for (int c = 0; c < 8; ++c) _mm256_store_ps(sd_t[k][c], q[c]);
    }
    for (int c = 0; c < cols; ++c) {
      for (int k = 0; k < 4; ++k) {
        const __m512d m = _mm512_load_pd(mu_t[k][c]);
        __m512d value = m;
        if (shot_noise) {
          // Means below kPoissonGaussMean (or NaN) take Rng::Poisson's exact draws.
          if (_mm512_cmp_pd_mask(m, gauss_from, _CMP_GE_OQ) != 0xFF) [[unlikely]] {
            Spill(v, words);
            ScalarLanes(words, mu_t[k][c], sd_t[k][c], shot_noise, read_sigma, out_t[k][c]);
            v = Reload(words);
            continue;
          }
          const __m256 noise = _mm256_mul_ps(_mm256_load_ps(sd_t[k][c]), Normal8(v, table, words));
          value = _mm512_add_pd(m, _mm512_cvtps_pd(noise));
        }
        if (read) {
          value =
              _mm512_add_pd(value, _mm512_mul_pd(vread, _mm512_cvtps_pd(Normal8(v, table, words))));
        }
        _mm256_store_ps(out_t[k][c], _mm512_cvtpd_ps(value));
      }
    }
    for (int k = 0; k < 4; ++k) {
      __m256 q[8];
      for (int c = 0; c < 8; ++c) q[c] = _mm256_load_ps(out_t[k][c]);
      Transpose8Ps(q);
      for (int j = 0; j < 8; ++j) _mm256_mask_storeu_ps(taps[j][k] + c0, in, q[j]);
    }
  }
}
TOFCAM_AVX512_DIAGNOSTICS_END
#endif

}  // namespace

void NoisyTapsRows(int rows, int n, std::size_t stride, const std::uint64_t* seeds, bool shot_noise,
                   double read_sigma, const double* const mu[4], const float* const sd[4],
                   float* const taps[][4]) {
#if defined(TOFCAM_AVX512_FORMS)
  if (rows == 8 && n > 0 && ::tofcam::internal::UseAvx512Forms()) {
    NoisyTaps8(n, stride, seeds, shot_noise, read_sigma, mu, sd, taps);
    return;
  }
#endif
  for (int j = 0; j < rows; ++j) {
    const std::size_t offset = static_cast<std::size_t>(j) * stride;
    const double* const mu_j[4] = {mu[0] + offset, mu[1] + offset, mu[2] + offset, mu[3] + offset};
    const float* const sd_j[4] = {sd[0] + offset, sd[1] + offset, sd[2] + offset, sd[3] + offset};
    NoisyTaps(n, seeds[j], shot_noise, read_sigma, mu_j, sd_j, taps[j]);
  }
}

Image<float> FixedPatternMap(const CameraModel& model) {
  const int width = model.intrinsics.width, height = model.intrinsics.height;
  Image<float> fpn_m(width, height, 0.f);
  Rng rng(model.unit_seed ^ 0xF1F0'0000'0000'0001ull);
  const double cx = model.intrinsics.cx_px, cy = model.intrinsics.cy_px;
  const double hx = std::max(cx, width - 1 - cx), hy = std::max(cy, height - 1 - cy);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      const double u = (c - cx) / std::max(hx, 1.0), v = (r - cy) / std::max(hy, 1.0);
      fpn_m(r, c) = static_cast<float>(model.fpn_bowl_m * 0.5 * (u * u + v * v) +
                                       model.fpn_spread_m * rng.Normal());
    }
  }
  return fpn_m;
}

}  // namespace tofcam::sim::internal

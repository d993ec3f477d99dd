#include "sensor.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <mutex>

#include "../core/fast_atan2.h"
#include "fast_math.h"
#include "hot_loop.h"
#include "optics.h"
#include "rng.h"
#include "tofcam/core/pixel_flags.h"

namespace tofcam::sim::internal {

namespace {

// Pixels with a tap above the full well (vectorised: a count rather than an early exit).
TOFCAM_SIM_LOOP std::size_t CountOverFullWell(std::size_t n, float full_well,
                                              const float* __restrict t0,
                                              const float* __restrict t1,
                                              const float* __restrict t2,
                                              const float* __restrict t3) {
  std::size_t count = 0;
  for (std::size_t i = 0; i < n; ++i) {
    count += static_cast<std::size_t>((t0[i] > full_well) | (t1[i] > full_well) |
                                      (t2[i] > full_well) | (t3[i] > full_well));
  }
  return count;
}

// One pixel of PixelMeans; `exact` uses libm for the phase shift (for shifts beyond the range of
// the polynomial).
inline void PixelMean(const SensorConstants& k, float re, float im, float dc, float sre, float sim,
                      float sdc, float fpn, bool exact, double& a_out, double& b_out,
                      double& cos_out, double& sin_out, double& shift_out) {
  const double x_re = (re + sre) * k.t_int_s;
  const double x_im = (im + sim) * k.t_int_s;
  b_out = (dc + sdc) * k.t_int_s + k.dark_e;
  const double a = std::sqrt(x_re * x_re + x_im * x_im);
  // Unit phasor of the measured phase; (0, 0) without signal, where the phase does not matter (it
  // is multiplied by a = 0). No select (GCC would turn one into a branch and keep the loop
  // scalar): adding 1e-300 changes no reachable amplitude (a float rate times >= 1 us of
  // integration is > 1e-51 electrons, and 1e-300 is below its rounding).
  const double inv_a = 1.0 / (a + 1e-300);
  const double cr = x_re * inv_a, ci = x_im * inv_a;
  // Wiggling: the odd harmonics make the error periodic in the measured phase phi with period
  // L/4, wiggle_m sin(4 phi + phase); sin 4phi and cos 4phi come from cos phi and sin phi by the
  // double-angle formulas (exact identities; no atan2 and sin per pixel).
  const double c2 = cr * cr - ci * ci, s2 = 2 * cr * ci;
  const double c4 = c2 * c2 - s2 * s2, s4 = 2 * c2 * s2;
  const double offset_m =
      k.global_offset_m + fpn + k.wiggle_m * (s4 * k.wiggle_cos + c4 * k.wiggle_sin);
  const double shift = offset_m * k.m_to_rad;
  double sn, cs;
  if (exact) {
    sn = std::sin(shift);
    cs = std::cos(shift);
  } else {
    SinCosSmallPoly(shift, sn, cs);
  }
  a_out = a;
  cos_out = cr * cs - ci * sn;
  sin_out = ci * cs + cr * sn;
  shift_out = shift;
}

// mu_k = B + A cos(phi - k pi / 2): cos, sin, -cos, -sin, all from one rendering.
TOFCAM_SIM_LOOP void TapMeans1(int n, const double* __restrict a, const double* __restrict b,
                               const double* __restrict cp, const double* __restrict sp,
                               double* __restrict mu0, double* __restrict mu1,
                               double* __restrict mu2, double* __restrict mu3) {
  for (int c = 0; c < n; ++c) {
    mu0[c] = b[c] + a[c] * cp[c];
    mu1[c] = b[c] + a[c] * sp[c];
    mu2[c] = b[c] - a[c] * cp[c];
    mu3[c] = b[c] - a[c] * sp[c];
  }
}

}  // namespace

// The loops below take __restrict pointers and are kept out of line (see hot_loop.h).

// Per pixel of a row of one rendering: amplitude a and offset b (electrons) and the unit phasor
// (cos, sin) of the measured phase including the systematic distance errors (fixed pattern,
// wiggling, drift, exposure offset). Vectorised; pixels whose shift leaves the polynomial's range
// are redone exactly.
TOFCAM_SIM_LOOP void PixelMeans(const SensorConstants& k, int n, const float* __restrict re,
                                const float* __restrict im, const float* __restrict dc,
                                const float* __restrict sre, const float* __restrict sim,
                                const float* __restrict sdc, const float* __restrict fpn,
                                double* __restrict a_out, double* __restrict b_out,
                                double* __restrict cos_out, double* __restrict sin_out,
                                double* __restrict shift) {
  for (int c = 0; c < n; ++c) {
    PixelMean(k, re[c], im[c], dc[c], sre[c], sim[c], sdc[c], fpn[c], false, a_out[c], b_out[c],
              cos_out[c], sin_out[c], shift[c]);
  }
  for (int c = 0; c < n; ++c) {
    if (!(std::abs(shift[c]) <= kSinCosSmallMax)) {
      PixelMean(k, re[c], im[c], dc[c], sre[c], sim[c], sdc[c], fpn[c], true, a_out[c], b_out[c],
                cos_out[c], sin_out[c], shift[c]);
    }
  }
}

// The tap means (tap k from rendering k when there are four) and the mean amplitude and offset
// over the renderings.
void TapMeans(int n, int slots, SensorRow& sr) {
  const std::size_t at = sr.RowOffset();
  double* mu[4] = {sr.mu[0].data() + at, sr.mu[1].data() + at, sr.mu[2].data() + at,
                   sr.mu[3].data() + at};
  if (slots == 1) {
    TapMeans1(n, sr.a[0].data(), sr.b[0].data(), sr.cos_p[0].data(), sr.sin_p[0].data(), mu[0],
              mu[1], mu[2], mu[3]);
    std::copy_n(sr.a[0].begin(), n, sr.a_mean.begin());
    std::copy_n(sr.b[0].begin(), n, sr.b_mean.begin());
    return;
  }
  for (int c = 0; c < n; ++c) {
    mu[0][c] = sr.b[0][c] + sr.a[0][c] * sr.cos_p[0][c];
    mu[1][c] = sr.b[1][c] + sr.a[1][c] * sr.sin_p[1][c];
    mu[2][c] = sr.b[2][c] - sr.a[2][c] * sr.cos_p[2][c];
    mu[3][c] = sr.b[3][c] - sr.a[3][c] * sr.sin_p[3][c];
    // Summed in slot order, as a running mean of a / 4 (exact scaling by a power of two).
    sr.a_mean[c] = sr.a[0][c] * 0.25 + sr.a[1][c] * 0.25 + sr.a[2][c] * 0.25 + sr.a[3][c] * 0.25;
    sr.b_mean[c] = sr.b[0][c] * 0.25 + sr.b[1][c] * 0.25 + sr.b[2][c] * 0.25 + sr.b[3][c] * 0.25;
  }
}

// Ground-truth causes of a row from rendering 0 as flag bits (multipath, scattering, mixed, no
// return, beyond range), branch-free so it vectorises; the same tests as Grab's `differ` for
// cos_bias >= 0 (the caller evaluates pixel by pixel otherwise): the angle between phasors a and
// b exceeds the bias when dot < 0 or dot^2 < cos_bias^2 |a|^2 |b|^2.
TOFCAM_SIM_LOOP void TruthCauses(int n, double cos_bias2, double t_int_s, double mixed_span_m,
                                 double range_m, const float* __restrict re,
                                 const float* __restrict im, const float* __restrict dre,
                                 const float* __restrict dim, const float* __restrict sre,
                                 const float* __restrict sim, const float* __restrict span,
                                 const float* __restrict td, std::uint16_t* __restrict bits) {
  const auto differ = [cos_bias2](double ar, double ai, double br, double bi) {
    const double dot = ar * br + ai * bi;
    const double norms2 = (ar * ar + ai * ai) * (br * br + bi * bi);
    return (dot < 0) | (dot * dot < cos_bias2 * norms2);
  };
  for (int c = 0; c < n; ++c) {
    const double ind_re = re[c] - dre[c], ind_im = im[c] - dim[c];
    const double ind2 = ind_re * ind_re + ind_im * ind_im;
    const double dir2 = static_cast<double>(dre[c]) * dre[c] + static_cast<double>(dim[c]) * dim[c];
    // Multipath: the indirect paths shift the phase noticeably, or outweigh the direct one.
    const bool multipath = (ind2 > 0) & ((ind2 >= dir2) | differ(re[c], im[c], dre[c], dim[c]));
    const double x_re = (re[c] + sre[c]) * t_int_s, x_im = (im[c] + sim[c]) * t_int_s;
    const bool scattering = ((sre[c] != 0) | (sim[c] != 0)) & differ(x_re, x_im, re[c], im[c]);
    const bool mixed = span[c] > mixed_span_m;
    const bool no_return = !(td[c] < kInf);
    const bool beyond = (td[c] >= range_m) & (td[c] < kInf);
    bits[c] =
        static_cast<std::uint16_t>((multipath ? static_cast<unsigned>(Flag::kMultipath) : 0u) |
                                   (scattering ? static_cast<unsigned>(Flag::kScattering) : 0u) |
                                   (mixed ? static_cast<unsigned>(Flag::kMixed) : 0u) |
                                   (no_return ? static_cast<unsigned>(Flag::kNoReturn) : 0u) |
                                   (beyond ? static_cast<unsigned>(Flag::kBeyondUnambiguous) : 0u));
  }
}

// Saturation physics on the noisy tap charges (electrons). A storage site holds at most the
// full well. Of a full site's excess, `overflow` spills over the barrier into the pixel's other
// sites, which share its photo-gate (filled evenly into the sites with room left): the taps of a
// saturating pixel equalise, so its offset keeps rising while its amplitude collapses. Of the
// charge that cannot stay in the pixel, `bloom` leaves it for the neighbours (Gaussian of
// blooming_sigma_px); the rest goes to the drain.
// Bloomed charge is charge, not light: it reaches a neighbour's photo-gate at times unrelated to
// the 20 MHz gate clock, so the neighbour's demodulation sorts it into its four taps equally on
// average. It raises the neighbour's offset (intensity) but not its amplitude, and each electron
// lands independently, so every tap receives a Poisson count of it (when shot noise is on):
// the extra noise eq. 2 predicts from the raised intensity.
// Returns true when charge bloomed; bloom_mean then holds the mean spill per tap of every pixel.
bool Saturate(std::vector<float> (&taps)[4], std::vector<float>& bloom_mean,
              std::vector<float>& tmp, int width, int height, double blooming_sigma_px,
              double full_well, double overflow, double bloom, std::uint64_t frame_seed,
              bool shot_noise, RowPool* pool) {
  const std::size_t np = taps[0].size();
  const std::size_t w = static_cast<std::size_t>(width);
  assert(np == w * static_cast<std::size_t>(height));  // every row is zeroed and scanned below
  const float fw = static_cast<float>(full_well);
  const float keep_share = static_cast<float>(overflow);
  const float out_share = static_cast<float>(bloom);
  bloom_mean.resize(np);  // zeroed row by row below
  // Most pixels hold no tap above the full well, and OverflowPixel leaves those as they are:
  // blocks without one are skipped after a vectorised count. The box of the spilling pixels
  // bounds the blur and the blooming noise below (zero elsewhere).
  int r0 = height, r1 = 0, c0 = width, c1 = 0;
  std::mutex box_mutex;
  RunRows(pool, height, [&](int ra, int rb) {
    const std::size_t begin = static_cast<std::size_t>(ra) * w;
    const std::size_t end = static_cast<std::size_t>(rb) * w;
    std::fill(bloom_mean.begin() + static_cast<std::ptrdiff_t>(begin),
              bloom_mean.begin() + static_cast<std::ptrdiff_t>(end), 0.f);
    int br0 = height, br1 = 0, bc0 = width, bc1 = 0;
    constexpr std::size_t kBlock = 64;
    for (std::size_t b = begin; b < end; b += kBlock) {
      const std::size_t block_end = std::min(end, b + kBlock);
      if (CountOverFullWell(block_end - b, fw, &taps[0][b], &taps[1][b], &taps[2][b],
                            &taps[3][b]) == 0) {
        continue;
      }
      for (std::size_t i = b; i < block_end; ++i) {
        float n[4];
        for (int k = 0; k < 4; ++k) n[k] = taps[k][i];
        const float out = OverflowPixel(n, fw, keep_share);
        for (int k = 0; k < 4; ++k) taps[k][i] = n[k];
        const float spill = out_share * out;
        if (spill > 0) {
          bloom_mean[i] = spill / 4;  // per tap of the receiving pixel
          const int r = static_cast<int>(i / w);
          const int c = static_cast<int>(i % w);
          br0 = std::min(br0, r);
          br1 = std::max(br1, r + 1);
          bc0 = std::min(bc0, c);
          bc1 = std::max(bc1, c + 1);
        }
      }
    }
    if (br1 > br0) {
      const std::lock_guard<std::mutex> lock(box_mutex);
      r0 = std::min(r0, br0);
      r1 = std::max(r1, br1);
      c0 = std::min(c0, bc0);
      c1 = std::max(c1, bc1);
    }
  });
  if (r1 <= r0) return false;  // nothing spilled
  const std::vector<float> kernel = GaussianKernel(blooming_sigma_px);
  BlurBoxInPlace(bloom_mean, tmp, width, height, kernel, r0, r1, c0, c1, pool);
  // Rows and columns beyond the blurred box have no bloom (their streams are not drawn from, as
  // before: a pixel without bloom draws nothing).
  const int radius = static_cast<int>(kernel.size() / 2);
  const int o_r0 = std::max(0, r0 - radius), o_r1 = std::min(height, r1 + radius);
  const int o_c0 = std::max(0, c0 - radius), o_c1 = std::min(width, c1 + radius);
  RunRows(pool, o_r1 - o_r0, [&](int a, int b) {
    for (int r = o_r0 + a; r < o_r0 + b; ++r) {
      Rng rng(frame_seed ^ 0xB10060000000000Dull ^
              (static_cast<std::uint64_t>(r) * 0xA24BAED4963EE407ull));
      for (int c = o_c0; c < o_c1; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * w + static_cast<std::size_t>(c);
        const float mean = bloom_mean[i];
        if (!(mean > 0)) continue;
        for (auto& tap : taps) {
          tap[i] += shot_noise ? static_cast<float>(rng.Poisson(mean)) : mean;
        }
      }
    }
  });
  return true;
}

namespace {

// std::round / std::llround of x >= 0 (half away from zero), exactly: x - floor(x) is exact for
// doubles below 2^52, so the comparison with 0.5 decides as the libm functions do.
inline double RoundNonNegative(double x) {
  const double f = std::floor(x);
  return f + ((x - f >= 0.5) ? 1.0 : 0.0);
}

// The vectorisable part of DemodulateRow; `redo` = 1 where the register is within 1e-5 of a tie.
TOFCAM_SIM_LOOP void DemodulateSpan(int n, const float* __restrict t0, const float* __restrict t1,
                                    const float* __restrict t2, const float* __restrict t3,
                                    bool clip, double full_well, double gain, int offset_register,
                                    std::uint16_t* __restrict distance,
                                    std::uint16_t* __restrict amplitude,
                                    std::uint16_t* __restrict intensity,
                                    std::uint8_t* __restrict saturated,
                                    std::uint8_t* __restrict redo) {
  const double two_pi = 2 * kPi;
  // Demodulate's clipping: a tap at or above the full well is set to it (with `clip`).
  auto clipped = [clip, full_well](float tap, bool& sat) {
    const double v = std::max(0.0, static_cast<double>(tap));
    const bool over = clip & (v >= full_well);
    sat |= over;
    return over ? full_well : v;
  };
  for (int c = 0; c < n; ++c) {
    bool sat = false;
    const double m0 = clipped(t0[c], sat), m1 = clipped(t1[c], sat);
    const double m2 = clipped(t2[c], sat), m3 = clipped(t3[c], sat);
    const double i_comp = m0 - m2, q_comp = m1 - m3;
    double phase = tofcam::internal::FastAtan2(q_comp, i_comp);
    phase += phase < 0 ? two_pi : 0.0;
    const double x = phase / two_pi * kDistanceRegisterSpan;
    const double frac = x - std::floor(x);
    redo[c] = static_cast<std::uint8_t>(std::abs(frac - 0.5) < 1e-5);
    const double reg = RoundNonNegative(x) + offset_register;
    distance[c] = static_cast<std::uint16_t>(static_cast<std::int32_t>(reg) & 0xFFFF);
    const double amp = std::sqrt(i_comp * i_comp + q_comp * q_comp) / 2;
    const double off = (m0 + m1 + m2 + m3) / 4;
    amplitude[c] = static_cast<std::uint16_t>(static_cast<std::int32_t>(
        std::min<double>(kMaxSignalRegister, RoundNonNegative(gain * amp))));
    intensity[c] = static_cast<std::uint16_t>(static_cast<std::int32_t>(
        std::min<double>(kMaxSignalRegister, RoundNonNegative(gain * off))));
    saturated[c] = static_cast<std::uint8_t>(sat | (gain * off > kMaxSignalRegister));
  }
}

}  // namespace

void DemodulateRow(int n, const float* const taps[4], bool clip, double full_well, double gain,
                   int offset_register, std::uint16_t* __restrict distance,
                   std::uint16_t* __restrict amplitude, std::uint16_t* __restrict intensity,
                   std::uint8_t* __restrict saturated) {
  thread_local std::vector<std::uint8_t> redo;
  redo.resize(static_cast<std::size_t>(n));
  DemodulateSpan(n, taps[0], taps[1], taps[2], taps[3], clip, full_well, gain, offset_register,
                 distance, amplitude, intensity, saturated, redo.data());
  for (int c = 0; c < n; ++c) {
    if (redo[c] == 0) continue;
    const float t[4] = {taps[0][c], taps[1][c], taps[2][c], taps[3][c]};
    const PixelRegisters px = Demodulate(t, clip, full_well, gain, offset_register);
    distance[c] = px.distance;
    amplitude[c] = px.amplitude;
    intensity[c] = px.intensity;
    saturated[c] = px.saturated ? 1 : 0;
  }
}

}  // namespace tofcam::sim::internal

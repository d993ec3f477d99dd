#pragma once
// Simulator stage 4, the sensor (internal to tofcam::sim, docs/simulator.md): the noiseless means
// of the four taps of each pixel (systematic distance errors included), the ground-truth causes,
// saturation with overflow and blooming, and demodulation with quantisation to registers.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "parallel.h"
#include "saturation.h"
#include "tofcam/core/units.h"

namespace tofcam::sim::internal {

/// Per-frame constants of the noiseless tap means.
struct SensorConstants {
  double t_int_s = 0;                                   ///< integration time, s
  double dark_e = 0;                                    ///< dark charge per tap, electrons
  double global_offset_m = 0;                           ///< warm-up drift plus exposure offset, m
  double wiggle_m = 0, wiggle_cos = 1, wiggle_sin = 0;  ///< wiggling amplitude (m) and phase
  double m_to_rad = 0;                                  ///< 2 pi / L, rad/m
};

/// Per thread: one row of the sensor stage, and the tap means and shot-noise sigmas of up to
/// kNoiseBlockRows rows waiting for their noise (NoisyTapsRows, src/sim/noise.h, draws eight
/// rows' streams at once on AVX-512 CPUs).
struct SensorRow {
  static constexpr int kNoiseBlockRows = 8;
  std::vector<double> a[4], b[4], cos_p[4], sin_p[4];  ///< per rendering (tap time)
  std::vector<double> shift;                           ///< phase shift (rad) of rendering 0..3
  std::vector<double> a_mean, b_mean;
  /// Tap means mu_k and sqrt(mu_k), the sigma of the Gaussian shot noise: the waiting rows one
  /// after the other, the current row (number block_rows) at RowOffset().
  std::vector<double> mu[4];
  std::vector<float> sd[4];
  std::vector<float> sigma, noise;    ///< truth sigma (m) and its denominator B + read variance
  std::vector<std::uint16_t> causes;  ///< truth cause bits
  std::uint64_t block_seed[kNoiseBlockRows] = {};  ///< random stream of each waiting row
  int block_row[kNoiseBlockRows] = {};             ///< frame row of each waiting row
  int block_rows = 0;                              ///< rows waiting
  int width = 0;
  [[nodiscard]] std::size_t RowOffset() const {
    return static_cast<std::size_t>(block_rows) * static_cast<std::size_t>(width);
  }
  void Resize(int n) {
    width = n;
    block_rows = 0;
    for (int k = 0; k < 4; ++k) {
      for (auto* v : {&a[k], &b[k], &cos_p[k], &sin_p[k]}) v->resize(n);
      mu[k].resize(static_cast<std::size_t>(kNoiseBlockRows) * n);
      sd[k].resize(static_cast<std::size_t>(kNoiseBlockRows) * n);
    }
    for (auto* v : {&shift, &a_mean, &b_mean}) v->resize(n);
    sigma.resize(n);
    noise.resize(n);
    causes.assign(n, 0);
  }
};

/// Per pixel of a row of one rendering (rates in electrons/s, plus the scattered rates and the
/// fixed-pattern offset in m): amplitude a = |x| and offset b = (dc + sdc) t + dark (electrons)
/// with x = (re + sre + i (im + sim)) t, and the unit phasor (cos, sin) of the measured phase
/// including the systematic distance errors (fixed pattern, wiggling, drift, exposure offset)
/// and that shift (rad).
void PixelMeans(const SensorConstants& k, int n, const float* __restrict re,
                const float* __restrict im, const float* __restrict dc, const float* __restrict sre,
                const float* __restrict sim, const float* __restrict sdc,
                const float* __restrict fpn, double* __restrict a_out, double* __restrict b_out,
                double* __restrict cos_out, double* __restrict sin_out, double* __restrict shift);

/// The tap means mu_k = B + A cos(phi - k pi / 2) (tap k from rendering k when slots = 4, all
/// from rendering 0 when slots = 1) and the mean amplitude and offset over the renderings.
void TapMeans(int n, int slots, SensorRow& sr);

/// Ground-truth causes of a row from rendering 0 as flag bits (multipath, scattering, mixed, no
/// return, beyond range): the angle between phasors a and b exceeds the bias when dot < 0 or
/// dot^2 < cos_bias2 |a|^2 |b|^2 (valid for cos_bias >= 0).
void TruthCauses(int n, double cos_bias2, double t_int_s, double mixed_span_m, double range_m,
                 const float* __restrict re, const float* __restrict im,
                 const float* __restrict dre, const float* __restrict dim,
                 const float* __restrict sre, const float* __restrict sim,
                 const float* __restrict span, const float* __restrict td,
                 std::uint16_t* __restrict bits);

/// Saturation physics on the noisy tap charges (electrons) of a width x height sensor; see the
/// comment at the definition. Returns true when charge bloomed; bloom_mean then holds the mean
/// spill per tap of every pixel. tmp is scratch.
/// Its row loops run on `pool` when one is given (rows are independent and each draws from its
/// own stream: the same values on any number of threads).
bool Saturate(std::vector<float> (&taps)[4], std::vector<float>& bloom_mean,
              std::vector<float>& tmp, int width, int height, double blooming_sigma_px,
              double full_well, double overflow, double bloom, std::uint64_t frame_seed,
              bool shot_noise, RowPool* pool = nullptr);

/// The registers of one pixel and whether it saturated.
struct PixelRegisters {
  std::uint16_t distance = 0, amplitude = 0, intensity = 0;
  bool saturated = false;  ///< a tap reached the full well or the intensity register clipped
};
/// Demodulates four tap charges (electrons): clipped at 0 and, with `clip`, at the full well;
/// phase atan2(n1 - n3, n0 - n2) in [0, 2 pi) to the distance register (plus the offset register,
/// modulo 2^16), amplitude sqrt(I^2 + Q^2) / 2 and offset (sum / 4) times the gain (registers per
/// electron), rounded and clipped at kMaxSignalRegister.
inline PixelRegisters Demodulate(const float taps[4], bool clip, double full_well, double gain,
                                 int offset_register) {
  const double two_pi = 2 * kPi;
  PixelRegisters out;
  double n[4];
  bool saturated = false;
  for (int k = 0; k < 4; ++k) {
    n[k] = std::max(0.0, static_cast<double>(taps[k]));
    if (clip && n[k] >= full_well) {
      n[k] = full_well;
      saturated = true;
    }
  }
  const double i_comp = n[0] - n[2], q_comp = n[1] - n[3];
  double phase = std::atan2(q_comp, i_comp);
  if (phase < 0) phase += two_pi;
  const double amp = std::sqrt(i_comp * i_comp + q_comp * q_comp) / 2;
  const double off = (n[0] + n[1] + n[2] + n[3]) / 4;
  long long reg = std::llround(phase / two_pi * kDistanceRegisterSpan) + offset_register;
  out.distance = static_cast<std::uint16_t>(reg & 0xFFFF);
  out.amplitude =
      static_cast<std::uint16_t>(std::min<double>(kMaxSignalRegister, std::round(gain * amp)));
  out.intensity =
      static_cast<std::uint16_t>(std::min<double>(kMaxSignalRegister, std::round(gain * off)));
  out.saturated = saturated || gain * off > kMaxSignalRegister;
  return out;
}

/// Demodulate over a row of n pixels (tap k's charges at taps[k]), registers into distance,
/// amplitude and intensity and 1 / 0 into `saturated`: the same registers as Demodulate, bit for
/// bit. The phase comes from a vectorised atan2 (error < 1e-6 of a distance register); where the
/// register value lies within 1e-5 of a rounding tie, the pixel is redone with Demodulate.
void DemodulateRow(int n, const float* const taps[4], bool clip, double full_well, double gain,
                   int offset_register, std::uint16_t* __restrict distance,
                   std::uint16_t* __restrict amplitude, std::uint16_t* __restrict intensity,
                   std::uint8_t* __restrict saturated);

}  // namespace tofcam::sim::internal

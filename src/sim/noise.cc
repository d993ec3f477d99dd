#include "noise.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include "hot_loop.h"
#include "rng.h"

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

void NoisyTaps(int n, std::uint64_t seed, bool shot_noise, double read_sigma,
               const double* const mu[4], const float* const sd[4], float* const taps[4]) {
  Rng rng(seed);
  for (int c = 0; c < n; ++c) {
    for (int k = 0; k < 4; ++k) {
      double v = mu[k][c];
      if (shot_noise) {
        // Rng::Poisson with sqrt(mean) precomputed (vectorised) in the Gaussian regime.
        v = v >= kPoissonGaussMean ? v + sd[k][c] * rng.Normal() : rng.Poisson(v);
      }
      if (read_sigma > 0) v += read_sigma * rng.Normal();
      taps[k][c] = static_cast<float>(v);
    }
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

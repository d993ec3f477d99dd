#pragma once
// Simulator stage 5, noise (internal to tofcam::sim, docs/simulator.md): the shot-noise scale of
// each tap and the ground-truth sigma, the seeded shot and read noise of a row of taps, and the
// unit's fixed-pattern offset map. The random numbers come from rng.h; every row of a frame has
// its own stream, so results do not depend on which thread ran the row.

#include <cstddef>
#include <cstdint>

#include "tofcam/core/image.h"
#include "tofcam/sim/camera_model.h"

namespace tofcam::sim::internal {

/// Per pixel of a row: the standard deviation sqrt(mu_k) of the Gaussian shot noise of each tap,
/// the noise variance B + read_var (electrons^2) and the ground-truth sigma
/// sigma_scale sqrt(B + read_var) / A (0 without signal), sigma_scale = L / (2 sqrt(2) pi).
void NoiseScales(int n, double read_var, double sigma_scale, const double* __restrict mu0,
                 const double* __restrict mu1, const double* __restrict mu2,
                 const double* __restrict mu3, const double* __restrict a_mean,
                 const double* __restrict b_mean, float* __restrict sd0, float* __restrict sd1,
                 float* __restrict sd2, float* __restrict sd3, float* __restrict sigma,
                 float* __restrict noise);

/// The seed of row r's random stream in the frame with seed frame_seed.
[[nodiscard]] inline std::uint64_t RowSeed(std::uint64_t frame_seed, int r) {
  return frame_seed ^ (static_cast<std::uint64_t>(r) * 0xA24BAED4963EE407ull);
}

/// Noisy tap charges of a row of n pixels from their means mu[k] (electrons) with one random
/// stream seeded by `seed`: per pixel and tap, in that order, a Poisson draw (Gaussian
/// mu + sd * N(0, 1) from kPoissonGaussMean on, sd = sqrt(mu)) when shot_noise is on, then
/// read_sigma * N(0, 1) when read_sigma > 0.
void NoisyTaps(int n, std::uint64_t seed, bool shot_noise, double read_sigma,
               const double* const mu[4], const float* const sd[4], float* const taps[4]);

/// NoisyTaps for `rows` rows of n pixels: row j has the stream seeds[j], the means and sigmas
/// mu[k] + j * stride and sd[k] + j * stride, and writes taps[j][k]. The same values bit for
/// bit as NoisyTaps row by row; on AVX-512 CPUs eight rows draw at once, one stream per vector
/// lane (rows == 8), otherwise the rows run one after the other.
void NoisyTapsRows(int rows, int n, std::size_t stride, const std::uint64_t* seeds, bool shot_noise,
                   double read_sigma, const double* const mu[4], const float* const sd[4],
                   float* const taps[][4]);

/// The unit's fixed-pattern offset map (m), width x height: a bowl reaching fpn_bowl_m at the
/// corners plus Gaussian pixel spread fpn_spread_m, seeded by the model's unit_seed.
[[nodiscard]] Image<float> FixedPatternMap(const CameraModel& model);

}  // namespace tofcam::sim::internal

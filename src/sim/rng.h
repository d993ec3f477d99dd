#pragma once
// Fast seeded random numbers for the simulator: xoshiro256++ (Blackman & Vigna), a table-based
// standard normal and a Poisson sampler (exact for small means, Gaussian above kPoissonGaussMean).

#include <array>
#include <cmath>
#include <cstdint>

namespace tofcam::sim::internal {

inline std::uint64_t SplitMix64(std::uint64_t& x) {
  std::uint64_t z = (x += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

/// Inverse normal CDF on a 4096-cell grid, interpolated linearly; the two outermost cells fall
/// back to Marsaglia's tail method so the tails are exact.
class NormalTable {
 public:
  static constexpr int kCells = 4096;
  NormalTable() {
    for (int i = 0; i <= kCells; ++i) {
      const double p = static_cast<double>(i) / kCells;
      values_[i] = static_cast<float>(InverseCdf(p));
    }
  }
  [[nodiscard]] float at(int i) const { return values_[i]; }
  /// The kCells + 1 grid values (for the AVX-512 form of NoisyTaps, src/sim/noise.cc).
  [[nodiscard]] const float* data() const { return values_.data(); }

 private:
  static double InverseCdf(double p) {
    if (p <= 0) return -8.0;
    if (p >= 1) return 8.0;
    double lo = -9, hi = 9;  // bisection on Phi(x) = erfc(-x / sqrt 2) / 2
    for (int it = 0; it < 80; ++it) {
      const double mid = 0.5 * (lo + hi);
      if (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p) {
        lo = mid;
      } else {
        hi = mid;
      }
    }
    return 0.5 * (lo + hi);
  }
  std::array<float, kCells + 1> values_{};
};

const NormalTable& GetNormalTable();

/// Poisson means from which on the sampler uses the Gaussian N(mean, mean).
inline constexpr double kPoissonGaussMean = 30.0;

class Rng {
 public:
  explicit Rng(std::uint64_t seed) { Seed(seed); }
  /// The generator continuing from a state taken with state() (the AVX-512 form of NoisyTaps
  /// runs eight streams in vector lanes and hands a lane to this class for its rare draws).
  static Rng FromState(const std::array<std::uint64_t, 4>& state) { return Rng(state); }
  [[nodiscard]] const std::array<std::uint64_t, 4>& state() const { return s_; }
  void Seed(std::uint64_t seed) {
    for (auto& w : s_) w = SplitMix64(seed);
  }
  std::uint64_t Next() {
    const std::uint64_t result = Rotl(s_[0] + s_[3], 23) + s_[0];
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = Rotl(s_[3], 45);
    return result;
  }
  /// Uniform in [0, 1).
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }
  /// Standard normal.
  float Normal() {
    const std::uint64_t r = Next();
    const int cell = static_cast<int>(r >> 52);  // 12 bits
    if (cell == 0 || cell == NormalTable::kCells - 1) return Tail(cell);
    const float frac = static_cast<float>((r >> 20) & 0xFFFFFFFFull) * 0x1.0p-32f;
    return table_.at(cell) + frac * (table_.at(cell + 1) - table_.at(cell));
  }
  /// The normal of a draw that fell in an outermost table cell (0 or kCells - 1): Marsaglia's
  /// exact tail sampler beyond the last table cell, from this stream's next uniforms.
  float Tail(int cell) {
    const double a = table_.at(NormalTable::kCells - 1);
    double x = 0, y = 0;
    do {
      x = -std::log(1.0 - Uniform()) / a;
      y = -std::log(1.0 - Uniform());
    } while (2 * y <= x * x);
    return static_cast<float>(cell == 0 ? -(a + x) : a + x);
  }
  /// Poisson with mean `mean` >= 0: exact (Knuth) below 30, Gaussian N(mean, mean) above.
  double Poisson(double mean) {
    if (mean <= 0) return 0;
    if (mean >= kPoissonGaussMean) return mean + std::sqrt(mean) * Normal();
    const double limit = std::exp(-mean);
    double p = Uniform();
    int k = 0;
    while (p > limit && k < 1000) {
      p *= Uniform();
      ++k;
    }
    return k;
  }

 private:
  explicit Rng(const std::array<std::uint64_t, 4>& state) : s_(state) {}
  static std::uint64_t Rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  std::array<std::uint64_t, 4> s_{};
  const NormalTable& table_ = GetNormalTable();
};

}  // namespace tofcam::sim::internal

#include "tofcam/optics/scattering.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <cstdint>
#include <string>
#include <vector>

#include "../filters/hot_loop.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

[[noreturn]] void Bad(const std::string& what) { throw Error(ErrorCode::kInvalidArgument, what); }

// Widths of three box passes whose combined variance is sigma² (Kovesi, "Fast almost-Gaussian
// filtering", 2010): odd widths wl and wl + 2, m passes of the first.
std::array<int, 3> BoxWidths(double sigma) {
  constexpr int n = 3;
  const double ideal = std::sqrt(12.0 * sigma * sigma / n + 1.0);
  int wl = static_cast<int>(std::floor(ideal));
  if (wl % 2 == 0) --wl;
  wl = std::max(wl, 1);
  const int wu = wl + 2;
  const double m_ideal =
      (12.0 * sigma * sigma - n * wl * wl - 4.0 * n * wl - 3.0 * n) / (-4.0 * wl - 4.0);
  const int m = std::clamp(static_cast<int>(std::lround(m_ideal)), 0, n);
  std::array<int, 3> w{};
  for (int i = 0; i < n; ++i) w[static_cast<std::size_t>(i)] = i < m ? wl : wu;
  return w;
}

// One centred box of odd `width` along each row, zero outside: a running sum per row. The
// running sum is a chain of dependent additions; four rows are summed side by side so that
// four chains overlap (each row's sums are exactly those of summing it alone).
void BoxRows(std::vector<float>& img, int w, int h, int width, std::vector<double>& prefix) {
  constexpr int kRows = 4;
  const int r = width / 2;
  const double inv = 1.0 / width;
  const std::size_t stride = static_cast<std::size_t>(w) + 1;
  prefix.resize(kRows * stride);
  // Output of one row from its prefix sums: the borders clamp the window, the interior does not.
  const auto finish = [&](float* line, const double* p) {
    const int left = std::min(r, w), right = std::max(left, w - r);
    for (int i = 0; i < left; ++i) {
      const int hi = std::min(i + r, w - 1);
      line[i] = static_cast<float>((p[hi + 1] - p[0]) * inv);
    }
    for (int i = left; i < right; ++i)
      line[i] = static_cast<float>((p[i + r + 1] - p[i - r]) * inv);
    for (int i = right; i < w; ++i) {
      const int lo = std::max(i - r, 0);
      line[i] = static_cast<float>((p[w] - p[lo]) * inv);
    }
  };
  int row = 0;
  for (; row + kRows <= h; row += kRows) {
    float* l0 = &img[static_cast<std::size_t>(row) * w];
    const float* l1 = l0 + w;
    const float* l2 = l1 + w;
    const float* l3 = l2 + w;
    double* p0 = prefix.data();
    double* p1 = p0 + stride;
    double* p2 = p1 + stride;
    double* p3 = p2 + stride;
    // The sums in registers: through the arrays each addition would wait for the previous
    // element's store to be forwarded.
    double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
    p0[0] = p1[0] = p2[0] = p3[0] = 0.0;
    for (int i = 0; i < w; ++i) {
      a0 += l0[i];
      a1 += l1[i];
      a2 += l2[i];
      a3 += l3[i];
      p0[i + 1] = a0;
      p1[i + 1] = a1;
      p2[i + 1] = a2;
      p3[i + 1] = a3;
    }
    for (int k = 0; k < kRows; ++k) finish(l0 + static_cast<std::size_t>(k) * w, p0 + k * stride);
  }
  for (; row < h; ++row) {
    float* line = &img[static_cast<std::size_t>(row) * w];
    double* p = prefix.data();
    double a = 0.0;
    p[0] = 0.0;
    for (int i = 0; i < w; ++i) {
      a += line[i];
      p[i + 1] = a;
    }
    finish(line, p);
  }
}

// sum[c] += in[c] (or -= with sign -1) and out[c] = sum[c] * inv over one row of columns:
// element-wise, so the AVX2 clone's four doubles per step give the same sums as one at a time.
TOFCAM_HOT_LOOP void AddRow(int w, const float* __restrict in, double* __restrict sum) {
  for (int c = 0; c < w; ++c) sum[c] += in[c];
}
TOFCAM_HOT_LOOP void SubtractRow(int w, const float* __restrict in, double* __restrict sum) {
  for (int c = 0; c < w; ++c) sum[c] -= in[c];
}
TOFCAM_HOT_LOOP void ScaleRow(int w, const double* __restrict sum, double inv,
                              float* __restrict out) {
  for (int c = 0; c < w; ++c) out[c] = static_cast<float>(sum[c] * inv);
}

// The same along each column, all columns at once row by row (contiguous, vectorises): the sum
// of rows [row - r, row + r] is kept per column and updated by one row in, one row out.
void BoxColumns(std::vector<float>& img, int w, int h, int width, std::vector<double>& sum,
                std::vector<float>& out) {
  const int r = width / 2;
  const double inv = 1.0 / width;
  sum.assign(static_cast<std::size_t>(w), 0.0);
  out.resize(img.size());
  for (int row = 0; row < std::min(r, h); ++row) {
    AddRow(w, &img[static_cast<std::size_t>(row) * w], sum.data());
  }
  for (int row = 0; row < h; ++row) {
    if (row + r < h) AddRow(w, &img[static_cast<std::size_t>(row + r) * w], sum.data());
    if (row - r - 1 >= 0) {
      SubtractRow(w, &img[static_cast<std::size_t>(row - r - 1) * w], sum.data());
    }
    ScaleRow(w, sum.data(), inv, &out[static_cast<std::size_t>(row) * w]);
  }
  img.swap(out);
}

// Almost-Gaussian blur of sigma, in place, zero padding.
void GaussBlur(std::vector<float>& img, int w, int h, double sigma) {
  thread_local std::vector<double> prefix;
  thread_local std::vector<float> out;
  for (int width : BoxWidths(sigma)) {
    if (width <= 1) continue;
    BoxRows(img, w, h, width, prefix);
    BoxColumns(img, w, h, width, prefix, out);
  }
}

// The usable pixels: the camera gave them a phasor.
bool Usable(const Frame& f, std::size_t i) {
  constexpr std::uint16_t kBad =
      static_cast<std::uint16_t>(Flag::kInvalid) | static_cast<std::uint16_t>(Flag::kSaturated);
  return f.amplitude[i] > 0 && (f.source_flags.empty() || !f.source_flags[i].Any(kBad));
}

// The frame's phasors (amplitude registers, phase of the distance register) and intensities.
struct Phasors {
  std::vector<float> re, im, dc;
  std::vector<std::uint8_t> usable;
};

Phasors ToPhasors(const Frame& f) {
  const std::size_t n = f.distance.size();
  Phasors p;
  p.re.assign(n, 0.0f);
  p.im.assign(n, 0.0f);
  p.dc.assign(n, 0.0f);
  p.usable.assign(n, 0);
  const double to_rad = 2.0 * kPi / kDistanceRegisterSpan;
  for (std::size_t i = 0; i < n; ++i) {
    if (!Usable(f, i)) continue;
    const double phi = f.distance[i] * to_rad;
    p.re[i] = static_cast<float>(f.amplitude[i] * std::cos(phi));
    p.im[i] = static_cast<float>(f.amplitude[i] * std::sin(phi));
    p.dc[i] = f.intensity[i];
    p.usable[i] = 1;
  }
  return p;
}

std::uint16_t ToRegister(double v) {
  return static_cast<std::uint16_t>(
      std::lround(std::clamp(v, 0.0, static_cast<double>(kMaxSignalRegister))));
}

}  // namespace

void ScatteringOptions::Validate() const {
  if (iterations < 1 || iterations > 20) {
    Bad("scattering.iterations = " + std::to_string(iterations) + " must be in [1, 20]");
  }
  double sum = 0.0;
  for (std::size_t l = 0; l < lobes.size(); ++l) {
    const ScatteringLobe& lobe = lobes[l];
    const std::string name = "scattering lobe " + std::to_string(l + 1);
    if (!(lobe.weight >= 0.0 && lobe.weight < 0.5)) {
      Bad(name + " weight = " + std::to_string(lobe.weight) + " must be in [0, 0.5)");
    }
    if (!(lobe.sigma_px > 0.0 && lobe.sigma_px <= 1000.0)) {
      Bad(name + " sigma_px = " + std::to_string(lobe.sigma_px) + " must be in (0, 1000]");
    }
    sum += lobe.weight;
  }
  if (!(sum < 0.5)) Bad("scattering lobes: the weights sum to " + std::to_string(sum) + " >= 0.5");
}

std::vector<float> ApplyScatteringPsf(std::span<const float> image, int width, int height,
                                      std::span<const ScatteringLobe> lobes) {
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (width <= 0 || height <= 0 || image.size() != n) {
    Bad("ApplyScatteringPsf: image of " + std::to_string(image.size()) + " values is not " +
        std::to_string(width) + " x " + std::to_string(height));
  }
  std::vector<float> out(n, 0.0f), tmp;
  for (const ScatteringLobe& lobe : lobes) {
    if (lobe.weight <= 0.0) continue;
    tmp.assign(image.begin(), image.end());
    GaussBlur(tmp, width, height, lobe.sigma_px);
    const float w = static_cast<float>(lobe.weight);
    for (std::size_t i = 0; i < n; ++i) out[i] += w * tmp[i];
  }
  return out;
}

void CompensateScatteringInto(const Frame& frame, const ScatteringOptions& options, Frame& out) {
  options.Validate();
  ValidateFrame(frame, "scattering compensation");
  out = frame;
  if (options.lobes.empty()) return;
  const int w = frame.width(), h = frame.height();
  const std::size_t n = frame.distance.size();
  const Phasors measured = ToPhasors(frame);
  Phasors z = measured;
  for (int k = 0; k < options.iterations; ++k) {
    const std::vector<float> sre = ApplyScatteringPsf(z.re, w, h, options.lobes);
    const std::vector<float> sim = ApplyScatteringPsf(z.im, w, h, options.lobes);
    const std::vector<float> sdc = ApplyScatteringPsf(z.dc, w, h, options.lobes);
    for (std::size_t i = 0; i < n; ++i) {
      if (!measured.usable[i]) continue;
      z.re[i] = measured.re[i] - sre[i];
      z.im[i] = measured.im[i] - sim[i];
      z.dc[i] = measured.dc[i] - sdc[i];
    }
  }
  const double to_register = kDistanceRegisterSpan / (2.0 * kPi);
  for (std::size_t i = 0; i < n; ++i) {
    if (!measured.usable[i]) continue;
    double phi = std::atan2(static_cast<double>(z.im[i]), static_cast<double>(z.re[i]));
    if (phi < 0) phi += 2.0 * kPi;
    const long reg = std::lround(phi * to_register);
    out.distance[i] = static_cast<std::uint16_t>(reg & 0xFFFF);
    out.amplitude[i] = ToRegister(std::hypot(z.re[i], z.im[i]));
    if (frame.info.has_intensity) out.intensity[i] = ToRegister(z.dc[i]);
  }
}

Frame CompensateScattering(const Frame& frame, const ScatteringOptions& options) {
  Frame out;
  CompensateScatteringInto(frame, options, out);
  return out;
}

void ScatteringFitOptions::Validate() const {
  if (sigma_grid_px.empty()) Bad("scattering fit: sigma_grid_px is empty");
  for (double s : sigma_grid_px) {
    if (!(s > 0.0 && s <= 1000.0)) {
      Bad("scattering fit: sigma " + std::to_string(s) + " must be in (0, 1000]");
    }
  }
  if (!(target_amplitude_ratio > 1.0 && target_amplitude_ratio <= 1e6)) {
    Bad("scattering fit: target_amplitude_ratio = " + std::to_string(target_amplitude_ratio) +
        " must be in (1, 1e6]");
  }
  if (guard_px < 0 || guard_px > 64) {
    Bad("scattering fit: guard_px = " + std::to_string(guard_px) + " must be in [0, 64]");
  }
}

ScatteringFit EstimateScatteringPsf(std::span<const Frame> without, std::span<const Frame> with,
                                    const ScatteringFitOptions& options) {
  options.Validate();
  if (without.empty() || with.empty()) Bad("scattering fit: needs frames with and without");
  const int w = without.front().width(), h = without.front().height();
  const int reg = without.front().info.integration_time_register;
  for (std::span<const Frame> set : {without, with}) {
    for (const Frame& f : set) {
      ValidateFrame(f, "scattering fit frame");
      if (f.width() != w || f.height() != h) Bad("scattering fit: frames differ in size");
      if (f.info.integration_time_register != reg) {
        Bad("scattering fit: frames differ in integration time (register " +
            std::to_string(f.info.integration_time_register) + " vs " + std::to_string(reg) + ")");
      }
    }
  }
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  // Mean phasors (the noise averages out; a pixel unusable in any frame is left out).
  auto mean = [&](std::span<const Frame> set, std::vector<std::complex<double>>& z,
                  std::vector<std::uint8_t>& ok) {
    z.assign(n, {0.0, 0.0});
    ok.assign(n, 1);
    for (const Frame& f : set) {
      const Phasors p = ToPhasors(f);
      for (std::size_t i = 0; i < n; ++i) {
        z[i] += std::complex<double>(p.re[i], p.im[i]);
        ok[i] = ok[i] && p.usable[i];
      }
    }
    for (auto& v : z) v /= static_cast<double>(set.size());
  };
  std::vector<std::complex<double>> z0, z1;
  std::vector<std::uint8_t> ok0, ok1;
  mean(without, z0, ok0);
  mean(with, z1, ok1);
  // The target: much brighter with than without (or clipped with: it is still the target).
  std::vector<std::uint8_t> target(n, 0);
  int target_pixels = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const bool bright = ok1[i] && std::abs(z1[i]) >= options.target_amplitude_ratio *
                                                         std::max(std::abs(z0[i]), 1.0);
    const bool clipped = !ok1[i] && ok0[i];
    if (bright || clipped) {
      target[i] = 1;
      ++target_pixels;
    }
  }
  if (target_pixels == 0) Bad("scattering fit: no pixel is brighter with the target");
  // Source of the stray light: the target's phasor minus the background it hides.
  std::vector<float> src_re(n, 0.0f), src_im(n, 0.0f);
  for (std::size_t i = 0; i < n; ++i) {
    if (!target[i] || !ok1[i]) continue;
    const std::complex<double> s = z1[i] - (ok0[i] ? z0[i] : std::complex<double>());
    src_re[i] = static_cast<float>(s.real());
    src_im[i] = static_cast<float>(s.imag());
  }
  // Fit pixels: usable in both, away from the target by guard_px.
  std::vector<std::size_t> fit;
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      if (!ok0[i] || !ok1[i] || target[i]) continue;
      bool near = false;
      for (int dr = -options.guard_px; dr <= options.guard_px && !near; ++dr) {
        for (int dc = -options.guard_px; dc <= options.guard_px && !near; ++dc) {
          const int rr = r + dr, cc = c + dc;
          near = rr >= 0 && rr < h && cc >= 0 && cc < w &&
                 target[static_cast<std::size_t>(rr) * w + cc];
        }
      }
      if (!near) fit.push_back(i);
    }
  }
  if (fit.size() < 100) {
    Bad("scattering fit: " + std::to_string(fit.size()) +
        " usable background pixels away from the target, need 100");
  }
  // Basis per width: G_sigma ⊛ source (unit weight), sampled at the fit pixels.
  const std::size_t g = options.sigma_grid_px.size();
  std::vector<Eigen::VectorXd> basis(g);
  Eigen::VectorXd d(static_cast<Eigen::Index>(2 * fit.size()));
  double energy = 0.0;
  for (std::size_t k = 0; k < fit.size(); ++k) {
    const std::complex<double> v = z1[fit[k]] - z0[fit[k]];
    d[static_cast<Eigen::Index>(2 * k)] = v.real();
    d[static_cast<Eigen::Index>(2 * k + 1)] = v.imag();
    energy += std::norm(v);
  }
  for (std::size_t s = 0; s < g; ++s) {
    const ScatteringLobe unit{1.0, options.sigma_grid_px[s]};
    const std::vector<float> bre = ApplyScatteringPsf(src_re, w, h, {&unit, 1});
    const std::vector<float> bim = ApplyScatteringPsf(src_im, w, h, {&unit, 1});
    basis[s].resize(static_cast<Eigen::Index>(2 * fit.size()));
    for (std::size_t k = 0; k < fit.size(); ++k) {
      basis[s][static_cast<Eigen::Index>(2 * k)] = bre[fit[k]];
      basis[s][static_cast<Eigen::Index>(2 * k + 1)] = bim[fit[k]];
    }
  }
  // Every single width and every pair, non-negative weights; the smallest residual wins.
  ScatteringFit best;
  double best_residual = energy;
  auto consider = [&](std::vector<std::size_t> idx) {
    const Eigen::Index m = static_cast<Eigen::Index>(idx.size());
    Eigen::MatrixXd a(d.size(), m);
    for (Eigen::Index j = 0; j < m; ++j) a.col(j) = basis[idx[static_cast<std::size_t>(j)]];
    const Eigen::VectorXd wts = (a.transpose() * a).ldlt().solve(a.transpose() * d);
    if ((wts.array() < 0.0).any() || !wts.allFinite()) return;
    const double residual = (d - a * wts).squaredNorm();
    if (residual < best_residual) {
      best_residual = residual;
      best.psf.lobes.clear();
      for (Eigen::Index j = 0; j < m; ++j) {
        best.psf.lobes.push_back({wts[j], options.sigma_grid_px[idx[static_cast<std::size_t>(j)]]});
      }
    }
  };
  for (std::size_t s = 0; s < g; ++s) consider({s});
  for (std::size_t s = 0; s < g; ++s) {
    for (std::size_t t = s + 1; t < g; ++t) consider({s, t});
  }
  best.target_pixels = target_pixels;
  best.fit_pixels = static_cast<int>(fit.size());
  best.explained_fraction = energy > 0.0 ? 1.0 - best_residual / energy : 0.0;
  return best;
}

}  // namespace tofcam

#pragma once
/// \file
/// Edge-preserving spatial smoothing of the distances, as camera SDKs offer it (ifm, pmd, Azure
/// Kinect: median and bilateral filters), with the support limited to one surface.
///
/// Only pixels without a reject bit (kRejectMask) and with a finite distance take part, as
/// centre or as support; rejected pixels are copied unchanged. The support of a pixel with
/// distance d is every usable pixel of its (2 r + 1)^2 window whose distance is within
/// max_jump_m of d (|d_n - d| <= max_jump_m in single precision; 0 = no limit): across a depth
/// step the two surfaces are never mixed, so the filter neither creates flying pixels nor rounds
/// edges.
///  - kMedian: the median of the support (the lower middle value for an even count). The 3x3
///    median of interior rows runs eight pixels at a time through a sorting network (same values).
///  - kBilateral: the mean of the support weighted by exp(-(d_n - d)^2 / (2 (k σ)^2)) / σ_n^2,
///    σ_n the neighbour's predicted σ (ΔL, m) and σ the centre's, k = range_sigma_factor: a
///    noisy neighbour counts less, and one further than a few σ from d hardly at all. Without
///    ΔL (or where it is not finite) σ = fallback_sigma_m.
/// A pixel with fewer than min_support pixels in its support (itself included) keeps its
/// distance. Flags, amplitude, intensity and ΔL are copied; ΔL is not lowered (the smoothed
/// value's σ depends on the support; the temporal filter tracks it for averages over time).

#include "tofcam/core/frame.h"

namespace tofcam {

enum class SpatialFilterKind { kMedian, kBilateral };

/// "median", "bilateral".
[[nodiscard]] std::string_view SpatialFilterKindName(SpatialFilterKind kind) noexcept;
/// Inverse of SpatialFilterKindName; Error(kInvalidArgument) naming the unknown kind.
[[nodiscard]] SpatialFilterKind ParseSpatialFilterKind(std::string_view name);

struct SpatialFilterOptions {
  SpatialFilterKind kind = SpatialFilterKind::kMedian;
  int radius_px = 1;                ///< Window half-size: 1 = 3x3, 2 = 5x5; [1, 3].
  double max_jump_m = 0.1;          ///< Support within this of the centre, m; >= 0, 0 = no limit.
  int min_support = 3;              ///< Pixels the support needs, the centre included; [1, 49].
  double range_sigma_factor = 2.0;  ///< kBilateral: k, (0, 100].
  double fallback_sigma_m = 0.02;   ///< kBilateral: σ where ΔL is missing, m; > 0.
  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// The frame with smoothed radial distances (see the file comment). Throws
/// Error(kInvalidArgument) for invalid options or channels of different sizes.
[[nodiscard]] MetricFrame SpatialFilter(const MetricFrame& frame,
                                        const SpatialFilterOptions& options);

/// The smoothed distances alone, into `distance_out` (resized; must not alias the frame's
/// distances): what the Pipeline uses, without copying the other channels.
void SpatialFilterInto(const MetricFrame& frame, const SpatialFilterOptions& options,
                       Image<float>& distance_out);

}  // namespace tofcam

#pragma once
/// \file
/// Stage 1 of the pipeline: SwissRanger registers to metric units.
///
///  - distance: d = ((reg - offset_reg) mod 65536) * L / 65536 m, L = c / (2 f_mod) (eq. 3) of
///    the frame's modulation frequency, so d is in [0, L);
///  - amplitude, intensity: copied as float register units (0..65532).
///
/// The camera adds its distance-offset register to every distance register (modulo 2^16).
/// By default the conversion takes it out again, so metric distances do not depend on that
/// register and the per-pixel calibration (measured with the register at 0, as the paper
/// prescribes) stays valid whatever the register is set to.

#include "tofcam/core/frame.h"

namespace tofcam {

struct MetricConversionOptions {
  /// Subtract FrameInfo::distance_offset_register (modulo 2^16) before scaling. False keeps the
  /// camera's shifted output as it is.
  bool remove_distance_offset_register = true;

  /// Nothing can be out of range today; kept so every stage validates the same way.
  void Validate() const;
};

/// Converts one frame. Flags: kInvalid where the amplitude register is 0 (a pixel with no
/// modulated return has a meaningless phase: the SwissRanger driver reports exactly 0 for
/// pixels it could not measure), OR-ed with `frame.source_flags` when present. `intensity` stays
/// empty when `!frame.info.has_intensity`. `delta_l_m` stays empty. Info and ground truth are
/// copied. Throws Error(kInvalidArgument) for an inconsistent frame (see ValidateFrame).
[[nodiscard]] MetricFrame ConvertToMetric(const Frame& frame,
                                          const MetricConversionOptions& options = {});

/// Same as ConvertToMetric, into `out`, reusing its buffers when they already have the frame's
/// size (no allocation in a steady loop: fresh buffers cost page faults that take longer than
/// the conversion itself). `out.delta_l_m` is cleared.
void ConvertToMetricInto(const Frame& frame, const MetricConversionOptions& options,
                         MetricFrame& out);

}  // namespace tofcam

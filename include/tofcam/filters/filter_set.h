#pragma once
/// \file
/// All filters behind one options struct, freely combined.

#include <memory>

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/pixel_flags.h"
#include "tofcam/filters/flying_pixel_filter.h"
#include "tofcam/filters/jump_edge_filter.h"
#include "tofcam/filters/pixel_filters.h"
#include "tofcam/filters/weingarten_cell_filter.h"

namespace tofcam {

/// One switch and one options struct per filter. Defaults: the paper's accuracy threshold and
/// the saturation rule on, everything else off.
struct FilterSetOptions {
  bool range_enabled = false;
  RangeOptions range;
  bool amplitude_enabled = false;
  AmplitudeThresholdOptions amplitude;
  bool saturation_enabled = true;
  SaturationOptions saturation;
  bool accuracy_enabled = true;
  AccuracyThresholdOptions accuracy;
  /// The camera's own confidence channel; no effect on sources without one.
  bool confidence_enabled = false;
  ConfidenceThresholdOptions confidence;
  bool flying_pixel_enabled = false;
  FlyingPixelOptions flying_pixel;
  bool jump_edge_enabled = false;
  JumpEdgeOptions jump_edge;
  bool weingarten_enabled = false;
  WeingartenCellOptions weingarten;

  /// Validates the options of every enabled filter.
  void Validate() const;
};

/// Runs the enabled filters in this order: the per-pixel ones (range, amplitude, saturation,
/// accuracy, confidence), then flying pixel, jump edge and Weingarten cells. Each neighbourhood
/// filter sees `frame.flags` plus everything raised before it as "already rejected", so it ignores
/// those neighbours; the cell filter comes last because it counts the points that survived. Returns
/// the union of the flags raised (not `frame.flags`); merge it with MergeFlags(). Throws like
/// the individual filters (e.g. kInvalidArgument when the accuracy filter is enabled and
/// `frame.delta_l_m` is empty, kMismatch when `rays` has another size).
[[nodiscard]] Image<PixelFlags> ApplyFilters(const MetricFrame& frame, const RayTable& rays,
                                             const FilterSetOptions& options);

/// Same as ApplyFilters, into `out`: its buffer is reused when it has the frame's size (no
/// allocation in a per-frame loop), every pixel is overwritten.
void ApplyFiltersInto(const MetricFrame& frame, const RayTable& rays,
                      const FilterSetOptions& options, Image<PixelFlags>& out);

/// ApplyFilters for one camera, as a stage that is built once: the options are validated and
/// everything the jump-edge and cell filters derive from the rays alone (the jump test's
/// constant per pair of neighbouring rays, the rays' bounding box) is computed at construction,
/// where ApplyFilters must check on every call that the rays are the ones it derived them from
/// (a comparison of the whole ray table, 240 KB at SR-2 size). Same flags as ApplyFilters, bit
/// for bit. Copies share the options, rays and prepared tables (all immutable); Process may run
/// on several threads at once. A moved-from FilterSet throws Error(kInvalidArgument) when used.
class FilterSet {
 public:
  /// `rays`: the camera's (MakeRayTable), kept by value. Throws Error(kInvalidArgument) for
  /// invalid options (as FilterSetOptions::Validate) and Error(kMismatch) when x, y and z differ
  /// in size.
  FilterSet(FilterSetOptions options, RayTable rays);

  /// The flags ApplyFiltersInto(frame, rays(), options(), out) raises, into `out` (reused when it
  /// has the frame's size, every pixel overwritten). Throws like ApplyFilters, e.g.
  /// Error(kMismatch) when the frame is not the rays' size and a ray filter is enabled.
  void Process(const MetricFrame& frame, Image<PixelFlags>& out) const;
  /// Same, into a fresh image.
  [[nodiscard]] Image<PixelFlags> Process(const MetricFrame& frame) const;

  [[nodiscard]] const FilterSetOptions& options() const;
  [[nodiscard]] const RayTable& rays() const;

 private:
  struct Prepared;
  [[nodiscard]] const Prepared& Get() const;
  std::shared_ptr<const Prepared> prepared_;
};

}  // namespace tofcam

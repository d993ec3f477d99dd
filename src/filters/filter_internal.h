#pragma once
// Shared by the filter implementations: input checks and the "into" forms that ApplyFilters
// chains without copying the frame (prior = what counts as already rejected, out = ORed into).

#include <optional>
#include <vector>

#include "hot_loop.h"
#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/pixel_flags.h"
#include "tofcam/filters/filter_set.h"
#include "tofcam/filters/flying_pixel_filter.h"
#include "tofcam/filters/jump_edge_filter.h"
#include "tofcam/filters/pixel_filters.h"
#include "tofcam/filters/weingarten_cell_filter.h"

namespace tofcam::filters_internal {

// kInvalidArgument unless the distance image is non-empty and every non-empty channel
// (amplitude, intensity, flags, delta_l_m) has its size.
void CheckFrame(const MetricFrame& frame, const char* filter);
// kMismatch unless all three ray images have the frame's size.
void CheckRays(const MetricFrame& frame, const RayTable& rays, const char* filter);

// `prior`'s pixels, or a zero-filled buffer of `n` flags when `prior` is empty, so hot loops need
// no null checks (valid until the next call on this thread).
const PixelFlags* PriorOrZeros(const Image<PixelFlags>& prior, std::size_t n);

// Per-pixel filters OR their bit into `out` (the frame's size).
void AccuracyInto(const MetricFrame& frame, const AccuracyThresholdOptions& o,
                  Image<PixelFlags>& out);
void AmplitudeInto(const MetricFrame& frame, const AmplitudeThresholdOptions& o,
                   Image<PixelFlags>& out);
void SaturationInto(const MetricFrame& frame, const SaturationOptions& o, Image<PixelFlags>& out);
void RangeInto(const MetricFrame& frame, const RangeOptions& o, Image<PixelFlags>& out);

// The jump-edge test's constant λ (jump_edge_filter.cc) of every pair of neighbouring rays at one
// angle: tables padded to (width + 2) x (height + 2), λ(p, p + offset) at p's padded index, +inf
// for pairs that leave the image.
struct JumpLambdas {
  int width = 0, height = 0;
  double angle_deg = 0.0;
  std::vector<float> east, south, south_east, south_west;
};
[[nodiscard]] JumpLambdas MakeJumpLambdas(const RayTable& rays, double angle_deg);

// The range of each ray component over a ray table: the cell filter bounds its box with it.
struct RayBounds {
  float x_lo = 0, x_hi = 0, y_lo = 0, y_hi = 0, z_lo = 0, z_hi = 0;
};
[[nodiscard]] RayBounds MakeRayBounds(const RayTable& rays);

// What the neighbourhood filters compute from the rays alone, made once per camera by FilterSet
// and Pipeline (the RayTable forms below recompute it, or validate a per-thread copy, per call).
struct PreparedRays {
  std::optional<JumpLambdas> lambdas;  // at the jump-edge filter's angle, when it is enabled
  RayBounds bounds;                    // when the cell filter is enabled
};
// For the enabled jump-edge and cell filters of `o`.
[[nodiscard]] PreparedRays PrepareRays(const RayTable& rays, const FilterSetOptions& o);

// Neighbourhood filters: `prior` (empty = nothing rejected) says which pixels to ignore.
void JumpEdgeInto(const MetricFrame& frame, const Image<PixelFlags>& prior, const RayTable& rays,
                  const JumpEdgeOptions& o, Image<PixelFlags>& out,
                  Image<PixelFlags>* echo = nullptr);
// With the λ tables of the frame's size made for the filter's angle. `echo` (may be null, may
// be `prior` itself: the filter has read all of prior before it writes) gets the same bits ORed
// in as `out`.
void JumpEdgeInto(const MetricFrame& frame, const Image<PixelFlags>& prior,
                  const JumpLambdas& lambdas, Image<PixelFlags>& out, Image<PixelFlags>* echo);
// `echo` as for JumpEdgeInto; it may be `prior`. The portable form writes row r's bits after it
// has read the rows up to r + 1 from prior and reads no row of prior twice; the AVX-512 form
// (column strips, which read their neighbours' columns and halo rows again) lists the raised
// pixels and writes the echo after its last read.
void FlyingPixelInto(const MetricFrame& frame, const Image<PixelFlags>& prior,
                     const FlyingPixelOptions& o, Image<PixelFlags>& out,
                     Image<PixelFlags>* echo = nullptr);
// The enabled flying-pixel, jump-edge and Weingarten filters of `o`, in ApplyFilters' order,
// ORing into `raised` (the frame's size); `frame.flags | raised` is what each treats as already
// rejected. The per-pixel filters of `o` are not run here.
// `prepared` (nullptr: computed or validated here) must come from PrepareRays(rays, o).
// `nothing_raised`: `raised` is all clear (no per-pixel filter ran before), which saves copying
// the frame's flags when a single neighbourhood filter is enabled.
void NeighbourhoodFiltersInto(const MetricFrame& frame, const RayTable& rays,
                              const PreparedRays* prepared, const FilterSetOptions& o,
                              Image<PixelFlags>& raised, bool nothing_raised = false);

void WeingartenInto(const MetricFrame& frame, const Image<PixelFlags>& prior, const RayTable& rays,
                    const WeingartenCellOptions& o, Image<PixelFlags>& out);
// With `bounds` = MakeRayBounds(rays).
void WeingartenInto(const MetricFrame& frame, const Image<PixelFlags>& prior, const RayTable& rays,
                    const RayBounds& bounds, const WeingartenCellOptions& o,
                    Image<PixelFlags>& out);

}  // namespace tofcam::filters_internal

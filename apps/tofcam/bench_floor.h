#pragma once
// How many sources the memcpy floor of `tofcam bench` cycles through (bench_command.cc), apart
// so that the arithmetic is tested on its own (tests/apps/bench_floor_test.cc). Not installed.
//
// A stage row reads the frame of its call (frame i mod the bench's frames) and touches buffers
// that are the same on every call: tables, its output, its state. The floor copies half the
// row's minimal traffic per call, from source r mod K into one reused destination. With K = 1
// (the floor before 2026-12-08) it touches twice that, which can stay in a cache the row's
// frames do not fit in; with K sources it touches (K + 1) halves. K is the largest count whose
// bytes stay within the row's own distinct bytes over the frames, so the floor never reaches
// further out in the memory hierarchy than the row does.

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace tofcam::cli {

/// The distinct bytes a pixel a stage row touches over the bench's cycle of frames. Both 0: not
/// stated, the floor is the hot one (one source).
struct Footprint {
  /// Bytes a pixel of the frame each call reads, other bytes for each frame (>= 0).
  double per_frame_bytes = 0;
  /// Bytes a pixel touched on every call alike: tables, the output, state; a buffer read and
  /// written in place counts once (>= 0).
  double fixed_bytes = 0;
};

/// Sources of traffic_bytes / 2 a pixel for the floor of a row with footprint `f` that cycles
/// through `frames` frames: the largest K >= 1 with (K + 1) x traffic / 2 <= frames x
/// per_frame + fixed, or 1 when the footprint is not stated, not larger than the traffic, or the
/// inputs are not finite and positive (traffic 0, NaN). At most `max_sources`.
[[nodiscard]] inline std::size_t FloorSources(double traffic_bytes, const Footprint& f,
                                              std::size_t frames, std::size_t max_sources) {
  const double half = traffic_bytes / 2;
  const double footprint = static_cast<double>(frames) * f.per_frame_bytes + f.fixed_bytes;
  if (!(half > 0) || !(footprint > 0) || !std::isfinite(footprint) || !std::isfinite(half)) {
    return 1;
  }
  const double k = std::floor(footprint / half - 1);
  if (!(k >= 1)) return 1;
  return std::max<std::size_t>(1,
                               std::min(max_sources, static_cast<std::size_t>(std::min(k, 1e9))));
}

}  // namespace tofcam::cli

#pragma once
// The memcpy floor of `tofcam bench` (bench_command.cc): how many sources it cycles through and
// the buffers it copies between, apart so that both are tested on their own
// (tests/apps/bench_floor_test.cc). Not installed.
//
// A stage row reads the frame of its call (frame i mod the bench's frames) and touches buffers
// that are the same on every call: tables, its output, its state. The floor copies half the
// row's minimal traffic per call, from source r mod K into one reused destination. With K = 1
// (the floor before 2026-12-08) it touches twice that, which can stay in a cache the row's
// frames do not fit in; with K sources it touches (K + 1) halves. K is the largest count whose
// bytes stay within the row's own distinct bytes over the frames, so the floor never reaches
// further out in the memory hierarchy than the row does. (Matching the distinct bytes is not
// matching where each access is served from: a row's fixed bytes are reused on every call, a
// floor's source every K calls. Where the fixed bytes are most of the footprint the floor can
// read more from far memory than the row does; docs/benchmarks.md names the rows.)

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>

#include "tofcam/core/error.h"

namespace tofcam::cli {

/// The distinct bytes a pixel a stage row touches over the bench's cycle of frames. Both 0: not
/// stated, the floor is the hot one (one source).
struct Footprint {
  /// Bytes a pixel the call reads from its own frame, other bytes for each frame of the cycle
  /// (>= 0).
  double per_frame_bytes = 0;
  /// Bytes a pixel touched on every call alike: tables, the output, state; a buffer read and
  /// written in place counts once (>= 0).
  double fixed_bytes = 0;
};

/// Sources of traffic_bytes / 2 a pixel for the floor of a row with footprint `f` that cycles
/// through `frames` frames: the largest K >= 1 with (K + 1) x traffic / 2 <= frames x
/// per_frame + fixed (to a relative 1e-9, so that a footprint of exactly K + 1 halves gives K
/// whatever the rounding of the division). 1 when the footprint is not stated or under 1.5 x the
/// traffic, or the inputs are not finite and positive (traffic 0, NaN). At most `max_sources`,
/// never 0.
[[nodiscard]] inline std::size_t FloorSources(double traffic_bytes, const Footprint& f,
                                              std::size_t frames, std::size_t max_sources) {
  const double half = traffic_bytes / 2;
  const double footprint = static_cast<double>(frames) * f.per_frame_bytes + f.fixed_bytes;
  if (!(half > 0) || !(footprint > 0) || !std::isfinite(footprint) || !std::isfinite(half)) {
    return 1;
  }
  const double k = std::floor(footprint / half * (1 + 1e-9) - 1);
  if (!(k >= 1)) return 1;
  return std::max<std::size_t>(1,
                               std::min(max_sources, static_cast<std::size_t>(std::min(k, 1e9))));
}

/// The floor's sources and destination: page-aligned, touched once, reused. The alignment is
/// fixed so the floor does not depend on where the allocator happens to place large blocks (with
/// the CLI's allocator policy, main.cc, they come from the heap; by default from fresh
/// mappings). Destination minus source is a multiple of 4096 then; glibc's memcpy copied such
/// buffers as fast as ones 64 or 2112 bytes apart on the Zen 5 of docs/benchmarks.md (60 KB to
/// 13 MB, five alternated rounds).
class CopyBuffers {
 public:
  /// Room for `sources` sources of `bytes` each, one after the other in one block, each at a
  /// page boundary, and a destination of `bytes`. Sources past 256 MiB in all are dropped: no
  /// cache holds them, and at 1 MP with many frames they would take gigabytes. Allocates (and
  /// touches) only when a block must grow; throws Error(kUnsupported) when it cannot.
  void Ensure(std::size_t bytes, std::size_t sources) {
    const std::size_t slot = (std::max<std::size_t>(bytes, 1) + kPage - 1) / kPage * kPage;
    const std::size_t count =
        std::clamp<std::size_t>(sources, 1, std::max<std::size_t>(1, kMaxSourceBytes / slot));
    Grow(src_, src_bytes_, slot * count, 1);
    Grow(dst_, dst_bytes_, slot, 0);
    slot_ = slot;
    count_ = count;
  }
  /// Source r mod the source count of the last Ensure (one page before any).
  [[nodiscard]] const char* src(std::size_t r) const { return src_.get() + (r % count_) * slot_; }
  [[nodiscard]] char* dst() const { return dst_.get(); }
  /// The source count of the last Ensure, after the cap.
  [[nodiscard]] std::size_t sources() const { return count_; }
  /// Bytes between one source and the next (a multiple of 4096).
  [[nodiscard]] std::size_t slot_bytes() const { return slot_; }

  static constexpr std::size_t kPage = 4096;
  static constexpr std::size_t kMaxSourceBytes = std::size_t{256} << 20;

 private:
  struct Free {
    void operator()(char* p) const { std::free(p); }
  };
  using Buffer = std::unique_ptr<char, Free>;
  static void Grow(Buffer& b, std::size_t& size, std::size_t need, int fill) {
    if (need <= size) return;
    b.reset();
    size = 0;
    b.reset(static_cast<char*>(std::aligned_alloc(kPage, need)));
    if (!b) {
      throw Error(ErrorCode::kUnsupported,
                  "bench: cannot allocate " + std::to_string(need) + " bytes for the memcpy floor");
    }
    std::memset(b.get(), fill, need);  // touched now: no page faults in the floor
    size = need;
  }
  Buffer src_ = Alloc(), dst_ = Alloc();
  std::size_t src_bytes_ = kPage, dst_bytes_ = kPage, slot_ = kPage, count_ = 1;
  static Buffer Alloc() {
    Buffer b(static_cast<char*>(std::aligned_alloc(kPage, kPage)));
    if (!b) throw Error(ErrorCode::kUnsupported, "bench: cannot allocate the memcpy floor");
    std::memset(b.get(), 0, kPage);
    return b;
  }
};

}  // namespace tofcam::cli

#include "bench_floor.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

namespace tofcam::cli {
namespace {

constexpr std::size_t kNoCap = std::numeric_limits<std::size_t>::max();

// Hand-computed: a row of traffic T cycling F frames with per-frame bytes p and fixed bytes x
// gets the largest K with (K + 1) T / 2 <= F p + x.
TEST(BenchFloorTest, SourcesFillTheRowsOwnBytesAndNoMore) {
  // Flying pixel: 12 B/px of traffic; distance, amplitude and flags of the frame (10), the output
  // flags (2). Four frames: 42 B/px; (6 + 1) x 6 = 42 exactly.
  EXPECT_EQ(FloorSources(12, {10, 2}, 4, kNoCap), 6u);
  // The cell filter: 20 B/px; 6 of the frame, rays and output 14. 4 x 6 + 14 = 38: K = 2 (30),
  // since K = 3 would touch 40.
  EXPECT_EQ(FloorSources(20, {6, 14}, 4, kNoCap), 2u);
  // The paper chain: 66 B/px, of which only the registers (6) are the frame's. 84 B/px over four
  // frames: two sources would touch 99, so one (the hot floor, 66).
  EXPECT_EQ(FloorSources(66, {6, 60}, 4, kNoCap), 1u);
  // The pan: five fixed frames a call, all bytes fixed (5 T): nine sources of T / 2 and the
  // destination touch 5 T.
  EXPECT_EQ(FloorSources(52, {0, 5 * 52}, 4, kNoCap), 9u);
  // A footprint of exactly K + 1 halves gives K whatever the division rounds to: 5 x this
  // traffic over its half came to 9.999999999999998 before the tolerance (a review's case).
  const double traffic = 26.677767141549637;
  EXPECT_EQ(FloorSources(traffic, {0, 5 * traffic}, 4, kNoCap), 9u);
  // More frames, more sources.
  EXPECT_EQ(FloorSources(12, {10, 2}, 16, kNoCap), 26u);  // 162 / 6 - 1 = 26
}

TEST(BenchFloorTest, TheHotFloorWhereTheRowTouchesNoMoreThanItsTraffic) {
  EXPECT_EQ(FloorSources(12, {}, 4, kNoCap), 1u);       // no footprint stated
  EXPECT_EQ(FloorSources(12, {10, 2}, 1, kNoCap), 1u);  // one frame: 12 = the traffic
  EXPECT_EQ(FloorSources(40, {4, 10}, 2, kNoCap), 1u);  // in place: 18 < 40
  EXPECT_EQ(FloorSources(12, {10, 2}, 0, kNoCap), 1u);  // no frames: 2 < 12
}

TEST(BenchFloorTest, BadInputsGiveTheHotFloorAndTheCapHolds) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(FloorSources(0, {10, 2}, 4, kNoCap), 1u);
  EXPECT_EQ(FloorSources(-12, {10, 2}, 4, kNoCap), 1u);
  EXPECT_EQ(FloorSources(nan, {10, 2}, 4, kNoCap), 1u);
  EXPECT_EQ(FloorSources(12, {nan, 2}, 4, kNoCap), 1u);
  EXPECT_EQ(FloorSources(12, {inf, 2}, 4, kNoCap), 1u);
  EXPECT_EQ(FloorSources(12, {-10, 2}, 4, kNoCap), 1u);
  EXPECT_EQ(FloorSources(12, {10, 2}, 4, 3), 3u);
  EXPECT_EQ(FloorSources(12, {10, 2}, 4, 0), 1u);  // never none
}

// Whatever the inputs, the floor's bytes ((K + 1) halves) stay within the row's footprint once
// it has more than one source, and one more source would pass it.
TEST(BenchFloorTest, TheFloorNeverReachesPastTheRow) {
  for (double traffic : {2.0, 8.0, 12.0, 20.0, 32.0, 66.0, 130.0}) {
    for (double per_frame : {0.0, 1.0, 4.0, 6.0, 10.0, 18.0}) {
      for (double fixed : {0.0, 2.0, 3.0, 14.0, 60.0}) {
        for (std::size_t frames : {1u, 2u, 4u, 8u, 1000u}) {
          const double footprint = static_cast<double>(frames) * per_frame + fixed;
          const std::size_t k = FloorSources(traffic, {per_frame, fixed}, frames, kNoCap);
          ASSERT_GE(k, 1u);
          if (k > 1) {
            EXPECT_LE((k + 1) * traffic / 2, footprint * (1 + 1e-9)) << traffic;
          }
          EXPECT_GT((k + 2) * traffic / 2, footprint) << traffic << " " << per_frame;
        }
      }
    }
  }
}

// The buffers: sources one slot apart, page-aligned, cycled by the repetition index; the cap at
// 256 MiB of sources; growing keeps the layout asked for last.
TEST(BenchFloorTest, CopyBuffersCycleTheirSourcesAndKeepTheCap) {
  CopyBuffers b;
  ASSERT_NE(b.src(0), nullptr);  // usable before any Ensure: one page
  EXPECT_EQ(b.sources(), 1u);
  b.Ensure(10'000, 3);
  EXPECT_EQ(b.sources(), 3u);
  EXPECT_EQ(b.slot_bytes(), 12'288u);  // 10,000 rounded up to pages
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(b.src(0)) % 4096, 0u);
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(b.dst()) % 4096, 0u);
  for (std::size_t r = 0; r < 7; ++r) EXPECT_EQ(b.src(r), b.src(0) + (r % 3) * 12'288) << r;
  // Copying every source's bytes touches no byte outside the block (the sanitizer build checks).
  for (std::size_t r = 0; r < 3; ++r) std::memcpy(b.dst(), b.src(r), 10'000);
  // Fewer sources later: the same block, the new count.
  b.Ensure(4096, 2);
  EXPECT_EQ(b.sources(), 2u);
  EXPECT_EQ(b.src(3), b.src(1));
  // The cap: 100 sources of 64 MiB are cut to 4 (256 MiB), one of 300 MiB stays one.
  b.Ensure(std::size_t{64} << 20, 100);
  EXPECT_EQ(b.sources(), 4u);
  std::memcpy(b.dst(), b.src(3), std::size_t{64} << 20);
  b.Ensure(std::size_t{300} << 20, 5);
  EXPECT_EQ(b.sources(), 1u);
  b.Ensure(4096, 0);
  EXPECT_EQ(b.sources(), 1u);  // never none
}

}  // namespace
}  // namespace tofcam::cli

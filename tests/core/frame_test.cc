#include "tofcam/core/frame.h"

#include <gtest/gtest.h>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

Frame MakeFrame(int w, int h) {
  Frame f;
  f.distance = Image<std::uint16_t>(w, h);
  f.amplitude = Image<std::uint16_t>(w, h);
  f.intensity = Image<std::uint16_t>(w, h);
  return f;
}

TEST(UnitsTest, UnambiguousRangeOfTwentyMegahertz) {
  // Paper eq. 3: L = c / (2 f) = 299792458 / 4e7 = 7.49481145 m ("7.5 m").
  EXPECT_NEAR(UnambiguousRangeM(20e6), 7.49481145, 1e-8);
  EXPECT_NEAR(UnambiguousRangeM(30e6), 4.99654097, 1e-8);
}

TEST(FrameTest, ValidateAcceptsConsistentFrame) {
  Frame f = MakeFrame(160, 124);
  EXPECT_NO_THROW(ValidateFrame(f));
  EXPECT_EQ(f.width(), 160);
  EXPECT_EQ(f.height(), 124);
}

TEST(FrameTest, ValidateRejectsMismatchedChannels) {
  Frame f = MakeFrame(160, 124);
  f.amplitude = Image<std::uint16_t>(160, 123);
  EXPECT_THROW(ValidateFrame(f), Error);
  f = MakeFrame(4, 4);
  f.truth = GroundTruth{Image<float>(4, 5), Image<PixelFlags>(4, 4), {}, {}, {}};
  EXPECT_THROW(ValidateFrame(f), Error);
  f.truth = GroundTruth{Image<float>(4, 4), Image<PixelFlags>(4, 4), {}, {}, {}};
  EXPECT_NO_THROW(ValidateFrame(f));
  f.truth->footprint_near_m = Image<float>(4, 4);  // near without far
  EXPECT_THROW(ValidateFrame(f), Error);
  f.truth->footprint_far_m = Image<float>(4, 4);
  EXPECT_NO_THROW(ValidateFrame(f));
  f.truth->sigma_m = Image<float>(3, 4);
  EXPECT_THROW(ValidateFrame(f), Error);
  f = MakeFrame(4, 4);
  f.info.modulation_frequency_hz = 0;
  EXPECT_THROW(ValidateFrame(f, "test frame"), Error);
  EXPECT_THROW(ValidateFrame(Frame{}), Error);
  f = MakeFrame(4, 4);
  f.source_flags = Image<PixelFlags>(3, 4);
  EXPECT_THROW(ValidateFrame(f), Error);
  f.source_flags = Image<PixelFlags>(4, 4);
  EXPECT_NO_THROW(ValidateFrame(f));
}

}  // namespace
}  // namespace tofcam

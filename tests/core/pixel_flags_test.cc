#include "tofcam/core/pixel_flags.h"

#include <gtest/gtest.h>

#include <set>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

TEST(PixelFlagsTest, SetClearHas) {
  PixelFlags f;
  EXPECT_TRUE(f.None());
  EXPECT_TRUE(f.Valid());
  f.Set(Flag::kSaturated).Set(Flag::kJumpEdge);
  EXPECT_TRUE(f.Has(Flag::kSaturated));
  EXPECT_TRUE(f.Has(Flag::kJumpEdge));
  EXPECT_FALSE(f.Has(Flag::kHighDeltaL));
  EXPECT_EQ(f.bits(), (1u << 1) | (1u << 4));
  f.Clear(Flag::kSaturated);
  EXPECT_EQ(f.bits(), 1u << 4);
  EXPECT_EQ((PixelFlags(Flag::kMixed) | Flag::kMultipath).bits(), (1u << 9) | (1u << 10));
  EXPECT_EQ((PixelFlags(0x00FF) & PixelFlags(Flag::kInvalid)).bits(), 1u);
}

TEST(PixelFlagsTest, FlagsAreDistinctSingleBits) {
  std::set<unsigned> seen;
  for (Flag f : kAllFlags) {
    const unsigned b = static_cast<unsigned>(f);
    EXPECT_EQ(b & (b - 1), 0u) << FlagName(f) << " is not a single bit";
    EXPECT_TRUE(seen.insert(b).second) << FlagName(f) << " repeats a bit";
  }
  EXPECT_EQ(seen.size(), 16u);  // the 16-bit field is full
}

TEST(PixelFlagsTest, RejectMaskCoversFilterFlagsOnly) {
  // Filter decisions reject a pixel; pure ground-truth causes do not.
  for (Flag f : {Flag::kInvalid, Flag::kSaturated, Flag::kLowAmplitude, Flag::kHighDeltaL,
                 Flag::kJumpEdge, Flag::kFlyingPixel, Flag::kOutOfRange, Flag::kSparseCell,
                 Flag::kInconsistent, Flag::kLowConfidence}) {
    EXPECT_FALSE(PixelFlags(f).Valid()) << FlagName(f);
  }
  // Decisions that only a pipeline makes are not truth causes (kSaturated is both).
  for (Flag f :
       {Flag::kLowAmplitude, Flag::kHighDeltaL, Flag::kInconsistent, Flag::kLowConfidence}) {
    EXPECT_FALSE(PixelFlags(f).Any(kTruthMask)) << FlagName(f);
  }
  for (Flag f : {Flag::kBeyondUnambiguous, Flag::kMixed, Flag::kMultipath, Flag::kScattering,
                 Flag::kNoReturn, Flag::kMotion}) {
    EXPECT_TRUE(PixelFlags(f).Valid()) << FlagName(f);
    EXPECT_TRUE(PixelFlags(f).Any(kTruthMask)) << FlagName(f);
  }
}

TEST(PixelFlagsTest, NamesRoundTripAndUnknownIsAnError) {
  for (Flag f : kAllFlags) EXPECT_EQ(ParseFlag(FlagName(f)), f);
  EXPECT_EQ(FlagsToString(PixelFlags()), "none");
  EXPECT_EQ(FlagsToString(PixelFlags(Flag::kSaturated) | Flag::kHighDeltaL),
            "saturated|high-delta-l");
  try {
    (void)ParseFlag("bogus");
    FAIL() << "no exception";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("bogus"), std::string::npos);
  }
}

}  // namespace
}  // namespace tofcam

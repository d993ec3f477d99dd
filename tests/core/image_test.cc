#include "tofcam/core/image.h"

#include <gtest/gtest.h>

#include <cstdint>

namespace tofcam {
namespace {

TEST(ImageTest, RowMajorLayout) {
  Image<int> img(3, 2);
  int v = 0;
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 3; ++c) img(r, c) = v++;
  // Element (r, c) lives at r * width + c.
  for (int i = 0; i < 6; ++i) EXPECT_EQ(img.data()[i], i);
  EXPECT_EQ(img(1, 0), 3);
  EXPECT_EQ(img.Row(1)[2], 5);
  EXPECT_EQ(img.size(), 6u);
}

TEST(ImageTest, FillConstructorAndEquality) {
  Image<std::uint16_t> a(4, 4, 7), b(4, 4, 7);
  EXPECT_EQ(a, b);
  b(3, 3) = 8;
  EXPECT_FALSE(a == b);
  Image<std::uint16_t> copy = b;  // value semantics: a deep copy
  copy(0, 0) = 1;
  EXPECT_EQ(b(0, 0), 7);
}

TEST(ImageTest, ViewsShareStorageAndCrop) {
  Image<int> img(4, 3, 0);
  ImageView<int> v = img.view();
  ImageView<int> crop = v.Crop(1, 2, 2, 2);
  EXPECT_EQ(crop.width(), 2);
  EXPECT_EQ(crop.height(), 2);
  EXPECT_EQ(crop.stride(), 4);
  crop(1, 1) = 42;  // (row 2, col 3) of the image
  EXPECT_EQ(img(2, 3), 42);
  ImageView<const int> cv = crop;
  EXPECT_EQ(cv(1, 1), 42);
  EXPECT_THROW((void)v.Crop(2, 2, 2, 2), Error);
  EXPECT_THROW((void)v.Crop(-1, 0, 1, 1), Error);
}

TEST(ImageTest, RejectsBadSizes) {
  EXPECT_THROW(Image<float>(-1, 5), Error);
  EXPECT_THROW(Image<float>(1 << 15, 1 << 15), Error);  // 2^30 pixels > 2^28 guard
  Image<float> empty(0, 0);
  EXPECT_TRUE(empty.empty());
}

#ifndef NDEBUG
TEST(ImageDeathTest, OutOfBoundsAccessAssertsInDebug) {
  Image<int> img(2, 2);
  EXPECT_DEATH((void)img(2, 0), "");
}
#endif

}  // namespace
}  // namespace tofcam

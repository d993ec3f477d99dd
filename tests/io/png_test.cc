#include "tofcam/io/png.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "../scratch_dir.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

namespace fs = std::filesystem;

fs::path Temp(const std::string& name) { return testing::ScratchDir("tofcam_png_") / name; }

TEST(PngTest, Rgb8RoundTrip) {
  Image<Rgb8> img(5, 3);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 5; ++c)
      img(r, c) = Rgb8{static_cast<std::uint8_t>(r * 50), static_cast<std::uint8_t>(c * 40), 7};
  const fs::path p = Temp("rgb.png");
  WritePngRgb8(p, img);
  // PNG signature written (independent check of the container).
  const std::string bytes = ReadFile(p);
  ASSERT_GE(bytes.size(), 8u);
  EXPECT_EQ(bytes.substr(1, 3), "PNG");
  EXPECT_EQ(ReadPngRgb8(p), img);
}

TEST(PngTest, Gray16RoundTripKeepsFullRange) {
  Image<std::uint16_t> img(4, 2);
  const std::uint16_t values[] = {0, 1, 255, 256, 32768, 65532, 65535, 4660};
  for (int i = 0; i < 8; ++i) img[i] = values[i];
  const fs::path p = Temp("gray.png");
  WritePngGray16(p, img);
  // PNG stores 16-bit samples big-endian: the first pixel row starts after filter byte 0.
  EXPECT_EQ(ReadPngGray16(p), img);
  EXPECT_THROW((void)ReadPngRgb8(Temp("missing.png")), Error);
}

TEST(PngTest, RejectsGarbageAndWrongKind) {
  const fs::path junk = Temp("junk.png");
  WriteFileAtomically(junk, "definitely not a png file");
  try {
    (void)ReadPngRgb8(junk);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFormat);
  }
  // A truncated PNG: header only.
  Image<Rgb8> img(64, 64, Rgb8{1, 2, 3});
  const fs::path full = Temp("full.png");
  WritePngRgb8(full, img);
  const std::string bytes = ReadFile(full);
  const fs::path cut = Temp("cut.png");
  WriteFileAtomically(cut, bytes.substr(0, bytes.size() / 2));
  EXPECT_THROW((void)ReadPngRgb8(cut), Error);
  // An RGB file is not a 16-bit grey one.
  EXPECT_THROW((void)ReadPngGray16(full), Error);
  EXPECT_THROW(WritePngRgb8(Temp("empty.png"), Image<Rgb8>()), Error);
}

}  // namespace
}  // namespace tofcam

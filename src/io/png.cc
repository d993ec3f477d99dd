#include "tofcam/io/png.h"

#include <png.h>

#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};

// libpng reports errors by longjmp; the handler stores the message for a proper Error.
void OnPngError(png_structp png, png_const_charp message) {
  auto* text = static_cast<std::string*>(png_get_error_ptr(png));
  if (text != nullptr) *text = message;
  png_longjmp(png, 1);
}
void OnPngWarning(png_structp, png_const_charp) {}

void WriteRows(const std::filesystem::path& path, int width, int height, int bit_depth,
               int color_type, const std::vector<png_bytep>& rows) {
  if (width <= 0 || height <= 0) {
    throw Error(ErrorCode::kInvalidArgument, path.string() + ": cannot write an empty image");
  }
  AtomicFile out(path);
  std::string message;
  png_structp png =
      png_create_write_struct(PNG_LIBPNG_VER_STRING, &message, OnPngError, OnPngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (png == nullptr || info == nullptr) {
    png_destroy_write_struct(&png, nullptr);
    throw Error(ErrorCode::kIo, path.string() + ": libpng could not start");
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw Error(ErrorCode::kIo, path.string() + ": PNG write failed: " + message);
  }
  png_init_io(png, out.file());
  png_set_IHDR(png, info, width, height, bit_depth, color_type, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_compression_level(png, 3);
  png_write_info(png, info);
  if (bit_depth == 16) png_set_swap(png);  // our pixels are little-endian; PNG is big-endian
  png_write_image(png, const_cast<png_bytepp>(rows.data()));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  out.Commit();
}

struct Decoded {
  int width = 0, height = 0;
  std::vector<unsigned char> bytes;
};

// Reads a PNG and converts it to `want` (PNG_COLOR_TYPE_RGB, 8 bit, or GRAY 16 bit).
Decoded ReadPng(const std::filesystem::path& path, bool want_gray16) {
  std::unique_ptr<std::FILE, FileCloser> f(std::fopen(path.c_str(), "rb"));
  if (!f) {
    throw Error(std::filesystem::exists(path) ? ErrorCode::kIo : ErrorCode::kNotFound,
                path.string() + ": cannot open PNG");
  }
  unsigned char sig[8] = {};
  if (std::fread(sig, 1, 8, f.get()) != 8 || png_sig_cmp(sig, 0, 8) != 0) {
    throw Error(ErrorCode::kFormat, path.string() + ": not a PNG file");
  }
  std::string message;
  png_structp png =
      png_create_read_struct(PNG_LIBPNG_VER_STRING, &message, OnPngError, OnPngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (png == nullptr || info == nullptr) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    throw Error(ErrorCode::kIo, path.string() + ": libpng could not start");
  }
  Decoded d;
  std::vector<png_bytep> rows;
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw Error(ErrorCode::kFormat, path.string() + ": corrupt PNG: " + message);
  }
  png_init_io(png, f.get());
  png_set_sig_bytes(png, 8);
  png_set_user_limits(png, 1 << 14, 1 << 14);
  png_read_info(png, info);
  const int color = png_get_color_type(png, info);
  const int depth = png_get_bit_depth(png, info);
  if (want_gray16) {
    if (color != PNG_COLOR_TYPE_GRAY || depth != 16) {
      png_destroy_read_struct(&png, &info, nullptr);
      throw Error(ErrorCode::kFormat, path.string() + ": expected a 16-bit greyscale PNG");
    }
    png_set_swap(png);
  } else {
    if (depth == 16) png_set_strip_16(png);
    if (color == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
    if (color == PNG_COLOR_TYPE_GRAY || color == PNG_COLOR_TYPE_GRAY_ALPHA) {
      if (depth < 8) png_set_expand_gray_1_2_4_to_8(png);
      png_set_gray_to_rgb(png);
    }
    if (color & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
    png_set_tRNS_to_alpha(png);
    png_set_strip_alpha(png);
  }
  png_read_update_info(png, info);
  d.width = static_cast<int>(png_get_image_width(png, info));
  d.height = static_cast<int>(png_get_image_height(png, info));
  const std::size_t row_bytes = png_get_rowbytes(png, info);
  const std::size_t expected_row = static_cast<std::size_t>(d.width) * (want_gray16 ? 2 : 3);
  if (row_bytes != expected_row) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw Error(ErrorCode::kFormat, path.string() + ": unsupported PNG pixel layout");
  }
  d.bytes.resize(row_bytes * d.height);
  rows.resize(d.height);
  for (int r = 0; r < d.height; ++r) rows[r] = d.bytes.data() + r * row_bytes;
  png_read_image(png, rows.data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return d;
}

}  // namespace

void WritePngRgb8(const std::filesystem::path& path, const Image<Rgb8>& image) {
  static_assert(sizeof(Rgb8) == 3);
  std::vector<png_bytep> rows(image.height());
  for (int r = 0; r < image.height(); ++r) {
    rows[r] = reinterpret_cast<png_bytep>(const_cast<Rgb8*>(image.Row(r).data()));
  }
  WriteRows(path, image.width(), image.height(), 8, PNG_COLOR_TYPE_RGB, rows);
}

void WritePngGray16(const std::filesystem::path& path, const Image<std::uint16_t>& image) {
  std::vector<png_bytep> rows(image.height());
  for (int r = 0; r < image.height(); ++r) {
    rows[r] = reinterpret_cast<png_bytep>(const_cast<std::uint16_t*>(image.Row(r).data()));
  }
  WriteRows(path, image.width(), image.height(), 16, PNG_COLOR_TYPE_GRAY, rows);
}

Image<Rgb8> ReadPngRgb8(const std::filesystem::path& path) {
  Decoded d = ReadPng(path, false);
  Image<Rgb8> out(d.width, d.height);
  std::memcpy(out.data(), d.bytes.data(), d.bytes.size());
  return out;
}

Image<std::uint16_t> ReadPngGray16(const std::filesystem::path& path) {
  Decoded d = ReadPng(path, true);
  Image<std::uint16_t> out(d.width, d.height);
  std::memcpy(out.data(), d.bytes.data(), d.bytes.size());
  return out;
}

}  // namespace tofcam

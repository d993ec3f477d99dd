#pragma once
/// \file
/// Image<T>: an owning, row-major, contiguous 2D array; ImageView<T>: a cheap non-owning view.
/// Pixel (row, col) is element row * width + col. Accessors are bounds-checked when NDEBUG is
/// not defined (debug and sanitizer builds) and unchecked in release builds.

#include <algorithm>
#include <cassert>
#include <cstddef>
#include <span>
#include <type_traits>
#include <vector>

#include "tofcam/core/error.h"

namespace tofcam {

/// Non-owning view of a row-major image with a row stride (in elements, >= width).
template <typename T>
class ImageView {
 public:
  ImageView() = default;
  ImageView(T* data, int width, int height, std::ptrdiff_t stride)
      : data_(data), width_(width), height_(height), stride_(stride) {}
  ImageView(T* data, int width, int height) : ImageView(data, width, height, width) {}

  /// Implicit conversion from a mutable view to a const view.
  template <typename U,
            typename = std::enable_if_t<std::is_same_v<const U, T> && !std::is_same_v<U, T>>>
  ImageView(const ImageView<U>& other)  // NOLINT(google-explicit-constructor)
      : ImageView(other.data(), other.width(), other.height(), other.stride()) {}

  [[nodiscard]] int width() const noexcept { return width_; }
  [[nodiscard]] int height() const noexcept { return height_; }
  [[nodiscard]] std::ptrdiff_t stride() const noexcept { return stride_; }
  [[nodiscard]] T* data() const noexcept { return data_; }
  [[nodiscard]] bool empty() const noexcept { return width_ == 0 || height_ == 0; }

  /// Element at (row, col); row in [0, height), col in [0, width).
  [[nodiscard]] T& operator()(int row, int col) const noexcept {
    assert(row >= 0 && row < height_ && col >= 0 && col < width_);
    return data_[row * stride_ + col];
  }
  /// One row as a span of `width` elements.
  [[nodiscard]] std::span<T> Row(int row) const noexcept {
    assert(row >= 0 && row < height_);
    return {data_ + row * stride_, static_cast<std::size_t>(width_)};
  }
  /// A rectangular sub-view; throws kInvalidArgument when the rectangle leaves the image.
  [[nodiscard]] ImageView Crop(int row0, int col0, int rows, int cols) const {
    if (row0 < 0 || col0 < 0 || rows < 0 || cols < 0 || row0 + rows > height_ ||
        col0 + cols > width_) {
      throw Error(ErrorCode::kInvalidArgument, "crop rectangle leaves the image");
    }
    return {data_ + row0 * stride_ + col0, cols, rows, stride_};
  }

 private:
  T* data_ = nullptr;
  int width_ = 0;
  int height_ = 0;
  std::ptrdiff_t stride_ = 0;
};

/// Owning row-major image with contiguous storage (stride == width). A value type: copies
/// deep-copy the pixels, moves are cheap.
template <typename T>
class Image {
 public:
  using value_type = T;

  Image() = default;
  /// A width x height image filled with `fill`. Throws kInvalidArgument for negative sizes or
  /// more than 2^28 pixels (a guard against hostile sizes from files).
  Image(int width, int height, const T& fill = T{}) : width_(width), height_(height) {
    if (width < 0 || height < 0) {
      throw Error(ErrorCode::kInvalidArgument, "image size must not be negative");
    }
    if (static_cast<long long>(width) * height > kMaxPixels) {
      throw Error(ErrorCode::kInvalidArgument, "image larger than 2^28 pixels");
    }
    data_.assign(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), fill);
  }

  static constexpr long long kMaxPixels = 1LL << 28;

  [[nodiscard]] int width() const noexcept { return width_; }
  [[nodiscard]] int height() const noexcept { return height_; }
  [[nodiscard]] std::size_t size() const noexcept { return data_.size(); }
  [[nodiscard]] bool empty() const noexcept { return data_.empty(); }
  [[nodiscard]] T* data() noexcept { return data_.data(); }
  [[nodiscard]] const T* data() const noexcept { return data_.data(); }
  [[nodiscard]] std::span<T> pixels() noexcept { return data_; }
  [[nodiscard]] std::span<const T> pixels() const noexcept { return data_; }

  /// Element at (row, col); row in [0, height), col in [0, width).
  [[nodiscard]] T& operator()(int row, int col) noexcept {
    assert(row >= 0 && row < height_ && col >= 0 && col < width_);
    return data_[static_cast<std::size_t>(row) * width_ + col];
  }
  [[nodiscard]] const T& operator()(int row, int col) const noexcept {
    assert(row >= 0 && row < height_ && col >= 0 && col < width_);
    return data_[static_cast<std::size_t>(row) * width_ + col];
  }
  /// Element at linear index i in [0, size()).
  [[nodiscard]] T& operator[](std::size_t i) noexcept {
    assert(i < data_.size());
    return data_[i];
  }
  [[nodiscard]] const T& operator[](std::size_t i) const noexcept {
    assert(i < data_.size());
    return data_[i];
  }
  [[nodiscard]] std::span<T> Row(int row) noexcept { return view().Row(row); }
  [[nodiscard]] std::span<const T> Row(int row) const noexcept { return view().Row(row); }

  [[nodiscard]] ImageView<T> view() noexcept { return {data_.data(), width_, height_}; }
  [[nodiscard]] ImageView<const T> view() const noexcept { return {data_.data(), width_, height_}; }

  void Fill(const T& value) { std::fill(data_.begin(), data_.end(), value); }
  [[nodiscard]] bool SameSize(int width, int height) const noexcept {
    return width_ == width && height_ == height;
  }
  template <typename U>
  [[nodiscard]] bool SameSize(const Image<U>& other) const noexcept {
    return width_ == other.width() && height_ == other.height();
  }

  friend bool operator==(const Image& a, const Image& b) {
    return a.width_ == b.width_ && a.height_ == b.height_ && a.data_ == b.data_;
  }

 private:
  int width_ = 0;
  int height_ = 0;
  std::vector<T> data_;
};

}  // namespace tofcam

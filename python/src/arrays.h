#pragma once
// NumPy views of tofcam images (zero copy: the array's base keeps the owning Python object, and
// with it the C++ buffer, alive) and checked conversions of NumPy arrays into images.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>

#include "tofcam/core/image.h"
#include "tofcam/core/pixel_flags.h"
#include "tofcam/core/rgb.h"

namespace tofcam::python {

namespace py = pybind11;

// NumPy element type of an image element: PixelFlags is its 16-bit field, Rgb8 three uint8.
template <typename T>
struct Element {
  using type = T;
  static constexpr int kChannels = 1;
};
template <>
struct Element<PixelFlags> {
  using type = std::uint16_t;
  static constexpr int kChannels = 1;
};
template <>
struct Element<Rgb8> {
  using type = std::uint8_t;
  static constexpr int kChannels = 3;
};

// (H, W) (or (H, W, 3) for Rgb8) writable view of `image`, whose lifetime `owner` guarantees.
// Returns None for an empty image (a channel the source does not have).
template <typename T>
py::object View(Image<T>& image, py::handle owner) {
  if (image.empty()) return py::none();
  using E = typename Element<T>::type;
  const auto h = static_cast<py::ssize_t>(image.height());
  const auto w = static_cast<py::ssize_t>(image.width());
  auto* data = reinterpret_cast<E*>(image.data());
  if constexpr (Element<T>::kChannels == 1) {
    return py::array_t<E>({h, w}, {w * py::ssize_t{sizeof(E)}, py::ssize_t{sizeof(E)}}, data,
                          owner);
  } else {
    constexpr py::ssize_t c = Element<T>::kChannels;
    return py::array_t<E>({h, w, c}, {w * c * py::ssize_t{sizeof(E)}, c, py::ssize_t{1}}, data,
                          owner);
  }
}

// The same for an owned image that Python takes over (a function's result): the array's base is
// a capsule that deletes the image.
template <typename T>
py::object Own(Image<T>&& image) {
  if (image.empty()) return py::none();
  auto* owned = new Image<T>(std::move(image));
  py::capsule base(owned, [](void* p) { delete static_cast<Image<T>*>(p); });
  return View(*owned, base);
}

// NumPy's name of an element type, for messages.
template <typename E>
constexpr const char* DtypeName() {
  if constexpr (std::is_same_v<E, std::uint16_t>) return "uint16";
  if constexpr (std::is_same_v<E, std::uint8_t>) return "uint8";
  if constexpr (std::is_same_v<E, float>) return "float32";
  if constexpr (std::is_same_v<E, double>) return "float64";
  return "?";
}

// A C-contiguous 2-D array of exactly element type E (no silent conversion). TypeError for
// another type or dtype, ValueError for another number of dimensions or a non-contiguous array;
// the messages name `name`.
py::array CheckArray(py::handle object, const char* name, const py::dtype& dtype,
                     const char* dtype_name, int channels = 1);

// Copies a checked array into a new image.
template <typename T>
Image<T> ToImage(py::handle object, const char* name) {
  using E = typename Element<T>::type;
  const py::array a =
      CheckArray(object, name, py::dtype::of<E>(), DtypeName<E>(), Element<T>::kChannels);
  Image<T> image(static_cast<int>(a.shape(1)), static_cast<int>(a.shape(0)));
  std::memcpy(static_cast<void*>(image.data()), a.data(), image.size() * sizeof(T));
  return image;
}

// Copies a checked array into `image` in place (views of the image stay valid and see the new
// values); an empty image takes the array's size. ValueError when the sizes differ.
template <typename T>
void Assign(Image<T>& image, py::handle object, const char* name) {
  if (image.empty()) {
    image = ToImage<T>(object, name);
    return;
  }
  using E = typename Element<T>::type;
  const py::array a =
      CheckArray(object, name, py::dtype::of<E>(), DtypeName<E>(), Element<T>::kChannels);
  if (a.shape(0) != image.height() || a.shape(1) != image.width()) {
    throw py::value_error(std::string(name) + " has shape (" + std::to_string(a.shape(0)) + ", " +
                          std::to_string(a.shape(1)) + "), the frame is (" +
                          std::to_string(image.height()) + ", " + std::to_string(image.width()) +
                          ")");
  }
  std::memcpy(static_cast<void*>(image.data()), a.data(), image.size() * sizeof(T));
}

}  // namespace tofcam::python

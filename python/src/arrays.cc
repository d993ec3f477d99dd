#include "arrays.h"

namespace tofcam::python {

py::array CheckArray(py::handle object, const char* name, const py::dtype& dtype,
                     const char* dtype_name, int channels) {
  if (!py::isinstance<py::array>(object)) {
    throw py::type_error(std::string(name) + " must be a numpy.ndarray of " + dtype_name +
                         ", got " + std::string(py::str(py::type::of(object).attr("__name__"))));
  }
  py::array a = py::reinterpret_borrow<py::array>(object);
  // Equivalent, not the same object: an array that went through pickle or another process has
  // its own dtype instance. Byte order still counts ('>f4' is not float32 here).
  if (py::detail::npy_api::get().PyArray_EquivTypes_(a.dtype().ptr(), dtype.ptr()) == 0) {
    throw py::type_error(std::string(name) + " must have dtype " + dtype_name + ", got " +
                         std::string(py::str(a.dtype())) + " (convert with .astype(np." +
                         dtype_name + "))");
  }
  const int ndim = channels == 1 ? 2 : 3;
  if (a.ndim() != ndim || (channels != 1 && a.shape(2) != channels)) {
    throw py::value_error(std::string(name) + " must have shape " +
                          (channels == 1 ? "(height, width)" : "(height, width, 3)") + ", got " +
                          std::to_string(a.ndim()) + " dimensions");
  }
  if (a.shape(0) <= 0 || a.shape(1) <= 0 || a.shape(0) > 1 << 15 || a.shape(1) > 1 << 15) {
    throw py::value_error(std::string(name) + " must be between 1 and 32768 pixels per side");
  }
  if ((a.flags() & py::array::c_style) == 0) {
    throw py::value_error(std::string(name) +
                          " must be C-contiguous (use numpy.ascontiguousarray)");
  }
  return a;
}

}  // namespace tofcam::python

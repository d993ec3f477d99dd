#include <pybind11/pybind11.h>

#include "bindings.h"
#include "tofcam/version.h"

PYBIND11_MODULE(_tofcam, m) {
  m.doc() =
      "tofcam: time-of-flight cameras for mobile robots (C++ core; see the `tofcam` package).";
  m.attr("__version__") = tofcam::kVersionString;
  tofcam::python::BindCore(m);
  tofcam::python::BindCamera(m);
  tofcam::python::BindPipeline(m);
  tofcam::python::BindStages(m);
  tofcam::python::BindIo(m);
}

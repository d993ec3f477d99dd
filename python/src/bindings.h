#pragma once
// The parts of the `tofcam` Python module, one function per source file (module.cc calls them in
// dependency order).

#include <pybind11/pybind11.h>

#include <string>

namespace tofcam::python {

namespace py = pybind11;

void BindCore(py::module_& m);      // errors, flags, frames, camera descriptions
void BindCamera(py::module_& m);    // cameras: simulator, playback, importers; scenes
void BindPipeline(py::module_& m);  // options (dict / YAML), pipeline, results, statistics
void BindStages(py::module_& m);    // stages as functions on frames and arrays, controllers
void BindIo(py::module_& m);        // recordings, calibration files and procedures, clouds

// "ClassName(a=1, b=2)" from a list of "key=value" parts.
std::string Repr(const char* name, std::initializer_list<std::string> fields);
std::string ReprValue(double v);

}  // namespace tofcam::python

#pragma once
// PipelineOptions as Python sees it: the options plus the keys the user gave (so that measured
// defaults fill only what was left out, exactly as the configuration file does).

#include <pybind11/pybind11.h>

#include <set>
#include <string>

#include "tofcam/pipeline/pipeline.h"

namespace tofcam::python {

struct PyPipelineOptions {
  PipelineOptions options;
  std::set<std::string> given_keys;
};

// Parses a nested dict through the configuration-file reader (same keys, types, validation).
PyPipelineOptions OptionsFromDict(const pybind11::dict& d, const std::string& source);
pybind11::dict OptionsToDict(const PyPipelineOptions& o);

}  // namespace tofcam::python

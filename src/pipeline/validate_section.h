#pragma once
// Internal to the pipeline stages' option structs.

#include <string>
#include <utility>

#include "tofcam/core/error.h"

namespace tofcam::pipeline_internal {

/// Runs `validate` and prefixes its message with the option section, so a message from a stage
/// ("max_delta_l_m must be ...") says where in the configuration the value lives.
template <typename F>
void ValidateSection(const char* section, F&& validate) {
  try {
    std::forward<F>(validate)();
  } catch (const Error& e) {
    throw Error(e.code(), std::string(section) + ": " + e.what());
  }
}

}  // namespace tofcam::pipeline_internal

#pragma once
// Checks every YAML reader of tofcam applies after parsing (src/io/pipeline_config.cc,
// src/io/calibration_file.cc, src/sim/yaml_util.h). Header-only: it needs yaml-cpp, which the
// core library does not link; each reader's library does. Not installed.

#include <yaml-cpp/yaml.h>

#include <set>
#include <string>
#include <vector>

#include "tofcam/core/error.h"

namespace tofcam::internal {

// Throws Error(kFormat) "<source>:<line>: key '<key>' appears twice in one mapping" for the first
// mapping anywhere in `root` that repeats a key. yaml-cpp keeps both pairs and `node[key]`
// returns the first, so without this check the later value (a correction, or a typo's target)
// would be dropped without a word. Each mapping and list is visited once, also when aliases
// refer to it many times (an alias is the same node, with the same position in the text).
inline void RejectDuplicateKeys(const YAML::Node& root, const std::string& source) {
  std::set<int> visited;  // text positions of the containers already checked
  std::vector<YAML::Node> stack{root};
  while (!stack.empty()) {
    const YAML::Node node = stack.back();
    stack.pop_back();
    if (!node || !(node.IsMap() || node.IsSequence())) continue;
    if (!visited.insert(node.Mark().pos).second) continue;
    if (node.IsSequence()) {
      for (const YAML::Node& item : node) stack.push_back(item);
      continue;
    }
    std::set<std::string> keys;
    for (auto it = node.begin(); it != node.end(); ++it) {
      if (it->first.IsScalar() && !keys.insert(it->first.Scalar()).second) {
        throw Error(ErrorCode::kFormat, source + ":" + std::to_string(it->first.Mark().line + 1) +
                                            ": key '" + it->first.Scalar() +
                                            "' appears twice in one mapping");
      }
      stack.push_back(it->second);
    }
  }
}

// Whether a scalar was written in quotes ("5", '5'): yaml-cpp tags such scalars "!" and plain
// ones "?". A reader that wants a number or a boolean refuses a quoted one, as it refuses any
// other string there.
inline bool IsQuoted(const YAML::Node& node) { return node.IsScalar() && node.Tag() == "!"; }

}  // namespace tofcam::internal

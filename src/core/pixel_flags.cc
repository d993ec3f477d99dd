#include "tofcam/core/pixel_flags.h"

#include "tofcam/core/error.h"

namespace tofcam {

std::string_view FlagName(Flag flag) noexcept {
  switch (flag) {
    case Flag::kInvalid:
      return "invalid";
    case Flag::kSaturated:
      return "saturated";
    case Flag::kLowAmplitude:
      return "low-amplitude";
    case Flag::kHighDeltaL:
      return "high-delta-l";
    case Flag::kJumpEdge:
      return "jump-edge";
    case Flag::kFlyingPixel:
      return "flying-pixel";
    case Flag::kOutOfRange:
      return "out-of-range";
    case Flag::kBeyondUnambiguous:
      return "beyond-unambiguous";
    case Flag::kSparseCell:
      return "sparse-cell";
    case Flag::kMixed:
      return "mixed";
    case Flag::kMultipath:
      return "multipath";
    case Flag::kScattering:
      return "scattering";
    case Flag::kNoReturn:
      return "no-return";
    case Flag::kMotion:
      return "motion";
    case Flag::kInconsistent:
      return "inconsistent";
    case Flag::kLowConfidence:
      return "low-confidence";
  }
  return "unknown";
}

std::string FlagsToString(PixelFlags flags) {
  std::string out;
  for (Flag f : kAllFlags) {
    if (flags.Has(f)) {
      if (!out.empty()) out += '|';
      out += FlagName(f);
    }
  }
  return out.empty() ? "none" : out;
}

Flag ParseFlag(std::string_view name) {
  for (Flag f : kAllFlags) {
    if (FlagName(f) == name) return f;
  }
  throw Error(ErrorCode::kInvalidArgument, "unknown pixel flag '" + std::string(name) + "'");
}

}  // namespace tofcam

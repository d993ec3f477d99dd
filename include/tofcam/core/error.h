#pragma once
/// \file
/// The one exception type of tofcam. Thrown only at boundaries (options, files, I/O),
/// never inside per-pixel loops.

#include <stdexcept>
#include <string>
#include <string_view>

namespace tofcam {

/// What went wrong, coarse enough for a caller to branch on.
enum class ErrorCode {
  kInvalidArgument,  ///< An option or argument is outside its valid range or malformed.
  kNotFound,         ///< A file, scene, camera model or dataset does not exist.
  kIo,               ///< Reading or writing failed (permissions, disk full, device).
  kFormat,           ///< A file exists but its content is malformed, truncated or hostile.
  kMismatch,         ///< Data is well formed but does not fit (e.g. calibration of another camera).
  kUnsupported,      ///< A valid request this build or source cannot serve.
  kInternal,         ///< A broken invariant: a bug in tofcam.
};

/// Stable lower-case name of an error code, e.g. "invalid-argument".
[[nodiscard]] std::string_view ErrorCodeName(ErrorCode code) noexcept;

/// Process exit status the CLI uses for an error code (always in 2..9, never 0 or 1).
[[nodiscard]] int ExitStatus(ErrorCode code) noexcept;

/// The exception tofcam throws. `what()` is a one-line, human-readable reason that names the
/// offending option, file or value.
class Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message);

  [[nodiscard]] ErrorCode code() const noexcept { return code_; }

 private:
  ErrorCode code_;
};

}  // namespace tofcam

#pragma once
/// \file
/// The pipeline configuration file: YAML with one section per stage (docs/pipeline.md lists
/// every key). `tofcam run --print-config` writes the defaults; `--config FILE` reads one back.
/// Keys that are left out keep their defaults; unknown keys and wrong types are errors, so a
/// typo cannot silently leave a default in place.

#include <filesystem>
#include <string>
#include <string_view>

#include "tofcam/pipeline/pipeline.h"

namespace tofcam {

/// Parses configuration text; `source` names it in messages. Throws Error(kFormat) naming the
/// source, the line and the key for malformed YAML, unknown keys, wrong types (e.g. a string
/// where a number belongs, a fraction for an integer) and unknown flag or controller names, and
/// Error(kInvalidArgument) naming the source and field for values out of range
/// (PipelineOptions::Validate). A relative `calibration.file` is resolved against `base_dir`
/// (unless `base_dir` is empty); the file is not read here.
[[nodiscard]] PipelineOptions ParsePipelineConfig(std::string_view yaml_text,
                                                  const std::string& source,
                                                  const std::filesystem::path& base_dir = {});

/// Reads and parses a configuration file (relative calibration paths resolve against the file's
/// folder). Error(kNotFound) for a missing file, otherwise as ParsePipelineConfig.
[[nodiscard]] PipelineOptions LoadPipelineConfig(const std::filesystem::path& path);

/// Every option as YAML, with a comment per key giving units and valid range; parsing the text
/// gives back `options` exactly (doubles are written in shortest round-trip form). The loaded
/// `calibration` itself is not part of the text, only `calibration_file`.
[[nodiscard]] std::string PipelineConfigToYaml(const PipelineOptions& options);

/// Loads `options.calibration_file` into `options.calibration` when a file is named and no
/// calibration is loaded yet (LoadCalibration's errors), then checks it fits `camera`
/// (CheckCalibrationMatches: Error(kMismatch) naming the field).
void LoadPipelineCalibration(PipelineOptions& options, const CameraInfo& camera);

}  // namespace tofcam

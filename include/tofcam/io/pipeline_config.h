#pragma once
/// \file
/// The pipeline configuration file: YAML with one section per stage (docs/pipeline.md lists
/// every key). `tofcam run --print-config` writes the defaults; `--config FILE` reads one back.
/// Keys that are left out keep their defaults; unknown keys and wrong types are errors, so a
/// typo cannot silently leave a default in place.

#include <filesystem>
#include <optional>
#include <set>
#include <string>
#include <string_view>

#include "tofcam/pipeline/pipeline.h"

namespace tofcam {

/// Parses configuration text; `source` names it in messages. Throws Error(kFormat) naming the
/// source, the line and the key for malformed YAML, unknown keys, a key given twice in one
/// mapping, wrong types (e.g. a string, quoted numbers included, where a number belongs, a
/// fraction for an integer) and unknown flag or controller names, and
/// Error(kInvalidArgument) naming the source and field for values out of range
/// (PipelineOptions::Validate). A relative `calibration.file` is resolved against `base_dir`
/// (unless `base_dir` is empty); the file is not read here. When `given_keys` is not null it
/// receives the dotted path of every key the text gives (e.g. "accuracy.scale"), so a caller can
/// tell an explicit value from a default (ApplyMeasuredDefaults).
[[nodiscard]] PipelineOptions ParsePipelineConfig(std::string_view yaml_text,
                                                  const std::string& source,
                                                  const std::filesystem::path& base_dir = {},
                                                  std::set<std::string>* given_keys = nullptr);

/// Reads and parses a configuration file (relative calibration paths resolve against the file's
/// folder). Error(kNotFound) for a missing file, otherwise as ParsePipelineConfig.
[[nodiscard]] PipelineOptions LoadPipelineConfig(const std::filesystem::path& path,
                                                 std::set<std::string>* given_keys = nullptr);

/// Every option as YAML, with a comment per key giving units and valid range; parsing the text
/// gives back `options` exactly (doubles are written in shortest round-trip form). The loaded
/// `calibration` itself is not part of the text, only `calibration_file`. Camera-specific keys
/// that ApplyMeasuredDefaults fills (accuracy.scale, the controller's set point) are printed
/// commented out while they hold their default, unless `given_keys` (from ParsePipelineConfig)
/// says the configuration set them: then they are printed, so the printed file pins them too.
[[nodiscard]] std::string PipelineConfigToYaml(const PipelineOptions& options,
                                               const std::set<std::string>* given_keys = nullptr);

/// Loads `options.calibration_file` into `options.calibration` when a file is named and no
/// calibration is loaded yet (LoadCalibration's errors), then checks it fits `camera`
/// (CheckCalibrationMatches: Error(kMismatch) naming the field). The same for
/// `alternate_calibration_file`, checked against the camera at the alternate frequency.
void LoadPipelineCalibration(PipelineOptions& options, const CameraInfo& camera);

}  // namespace tofcam

namespace tofcam {

/// Where ApplyMeasuredDefaults took each camera-specific value from, for status lines.
struct MeasuredDefaults {
  std::string delta_l_scale;  ///< e.g. "the calibration file's noise calibration (30 ...)".
  std::string controller;     ///< I_A, V_p and c_0.
  std::string scattering;     ///< The scattering compensation's point-spread.
};

/// Fills the camera-specific options the configuration left at their defaults from what was
/// measured on this camera, so that defaults stay sensible on any camera:
///  - accuracy.scale: the loaded calibration's noise calibration, else `source_delta_l_scale`
///    (what the camera source knows, e.g. an importer's fit or a simulator's ground-truth σ;
///    `source_note` says where it came from), else the default 1 (eq. 2 as printed);
///  - controller.target_intensity / gain_register_per_intensity / bias_register: the loaded
///    calibration's controller set point (the kind is left alone);
///  - scattering: the loaded calibration's point-spread turns the compensation on with its
///    lobes, unless the configuration gives any `scattering.*` key.
/// Keys in `given_keys` (from ParsePipelineConfig) are never changed. Call after
/// LoadPipelineCalibration. Throws Error(kInvalidArgument) if the result does not validate.
[[nodiscard]] MeasuredDefaults ApplyMeasuredDefaults(
    PipelineOptions& options, const std::set<std::string>& given_keys,
    std::optional<double> source_delta_l_scale = std::nullopt, const std::string& source_note = {});

}  // namespace tofcam

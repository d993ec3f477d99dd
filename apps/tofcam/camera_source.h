#pragma once
// Camera sources for the CLI: `--camera <kind>:<rest>`, e.g. `sim:pavilion`, `file:rec.h5`,
// `import:ifm-o3d3xx:path.h5`. Each kind registers a factory from its own file with
// TOFCAM_REGISTER_CAMERA_SOURCE, so adding a source touches no shared code.

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>

#include "tofcam/core/camera.h"

namespace tofcam::cli {

/// Options every source may honour (a source ignores what does not apply to it).
struct CameraSourceOptions {
  std::uint64_t seed = 1;  ///< Simulator noise seed.
  bool real_time = false;  ///< Throttle to the camera's frame rate (simulator, playback).
  bool loop = false;       ///< Playback: start again at the end.
  int integration_time_register = 0;  ///< 0 = the source's default.
  std::string camera_model;           ///< Simulator: camera model name or YAML file; "" = SR-2.
  int ros2_domain = 0;                ///< ROS 2 source: DDS domain unless its spec names one.
};

using CameraFactory =
    std::function<std::unique_ptr<Camera>(const std::string& rest, const CameraSourceOptions&)>;

struct CameraSourceKind {
  std::string help;  ///< One line for --help, e.g. "sim:<scene|file.yaml>  simulated camera".
  CameraFactory factory;
  /// false: Grab() never runs out (the simulator), so "all frames" is no count. (A ROS 2 stream
  /// ends when no frame comes within its timeout.)
  bool ends = true;
};

std::map<std::string, CameraSourceKind>& CameraSourceRegistry();
bool RegisterCameraSource(const std::string& kind, CameraSourceKind source);

/// Opens `spec` = "<kind>:<rest>". Throws Error(kInvalidArgument) listing the known kinds when
/// the kind is unknown or the spec has no ':'.
[[nodiscard]] std::unique_ptr<Camera> OpenCamera(const std::string& spec,
                                                 const CameraSourceOptions& options);

/// Whether the source `spec` names ends by itself (CameraSourceKind::ends); true for an unknown
/// kind (OpenCamera reports that one).
[[nodiscard]] bool CameraSourceEnds(const std::string& spec);

/// Help text listing every registered source, for option descriptions.
[[nodiscard]] std::string CameraSourceHelp();

}  // namespace tofcam::cli

#define TOFCAM_REGISTER_CAMERA_SOURCE(kind, help, factory)       \
  [[maybe_unused]] static const bool tofcam_registered_source_ = \
      ::tofcam::cli::RegisterCameraSource(kind, {help, factory, true})
// A source that may never run out (CameraSourceKind::ends false).
#define TOFCAM_REGISTER_ENDLESS_CAMERA_SOURCE(kind, help, factory) \
  [[maybe_unused]] static const bool tofcam_registered_source_ =   \
      ::tofcam::cli::RegisterCameraSource(kind, {help, factory, false})

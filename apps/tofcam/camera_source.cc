#include "camera_source.h"

#include "tofcam/core/error.h"

namespace tofcam::cli {

std::map<std::string, CameraSourceKind>& CameraSourceRegistry() {
  static std::map<std::string, CameraSourceKind> registry;
  return registry;
}

bool RegisterCameraSource(const std::string& kind, CameraSourceKind source) {
  CameraSourceRegistry().emplace(kind, std::move(source));
  return true;
}

std::string CameraSourceHelp() {
  std::string out;
  for (const auto& [kind, source] : CameraSourceRegistry()) {
    if (!out.empty()) out += "; ";
    out += source.help;
  }
  return out.empty() ? "(no camera sources built)" : out;
}

bool CameraSourceEnds(const std::string& spec) {
  const auto it = CameraSourceRegistry().find(spec.substr(0, spec.find(':')));
  return it == CameraSourceRegistry().end() || it->second.ends;
}

std::unique_ptr<Camera> OpenCamera(const std::string& spec, const CameraSourceOptions& options) {
  const auto colon = spec.find(':');
  const std::string kind = colon == std::string::npos ? spec : spec.substr(0, colon);
  const auto it = CameraSourceRegistry().find(kind);
  if (colon == std::string::npos || it == CameraSourceRegistry().end()) {
    throw Error(ErrorCode::kInvalidArgument,
                "--camera '" + spec + "': expected <kind>:<source>, one of: " + CameraSourceHelp());
  }
  return it->second.factory(spec.substr(colon + 1), options);
}

}  // namespace tofcam::cli

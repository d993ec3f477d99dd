// Camera source `import:<format>:<path>`: real camera data through the importers.
#include <memory>
#include <string>

#include "camera_source.h"
#include "tofcam/io/importers.h"

namespace tofcam::cli {
namespace {

std::unique_ptr<Camera> OpenImport(const std::string& rest, const CameraSourceOptions& o) {
  auto camera = std::make_unique<ImportedCamera>(ImportFromSpec(rest), o.loop);
  if (o.integration_time_register != 0) {
    camera->SetIntegrationTimeRegister(o.integration_time_register);
  }
  return camera;
}

TOFCAM_REGISTER_CAMERA_SOURCE(
    "import",
    "import:<format>:<path>  real camera files (ifm-o3d3xx, adi-interleaved, adi-raw, "
    "azure-kinect, mesa-dat)",
    OpenImport);

}  // namespace
}  // namespace tofcam::cli

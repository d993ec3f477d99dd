// Camera source `sim:<scene|file.yaml>[?param=value&...]`: the simulated camera.
#include <memory>
#include <string>

#include "camera_source.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::cli {
namespace {

std::unique_ptr<Camera> OpenSimCamera(const std::string& rest, const CameraSourceOptions& options) {
  const auto [scene_name, overrides] = sim::ParseSceneSpec(rest);
  sim::SimulatorOptions sim_options;
  sim_options.seed = options.seed;
  sim_options.real_time = options.real_time;
  sim_options.integration_time_register = options.integration_time_register;
  return std::make_unique<sim::SimulatedCamera>(sim::ResolveScene(scene_name, overrides),
                                                sim::ResolveCameraModel(options.camera_model),
                                                sim_options);
}

TOFCAM_REGISTER_ENDLESS_CAMERA_SOURCE(
    "sim",
    "sim:<scene|file.yaml>[?param=value&...]  simulated camera (scenes: wall, hand, pavilion, "
    "mirror, lamps, corridor, beyond-range, demo, approach)",
    OpenSimCamera);

}  // namespace
}  // namespace tofcam::cli

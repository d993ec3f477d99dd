// Camera source `file:<recording.h5>`: plays a tofcam recording (PlaybackCamera).
#include <memory>
#include <string>

#include "camera_source.h"
#include "tofcam/io/recording.h"

namespace tofcam::cli {
namespace {

std::unique_ptr<Camera> OpenRecording(const std::string& rest, const CameraSourceOptions& o) {
  PlaybackOptions options;
  options.real_time = o.real_time;
  options.loop = o.loop;
  auto camera = std::make_unique<PlaybackCamera>(rest, options);
  // A recording cannot change its integration time: asking for another value is an error
  // (kUnsupported) rather than silently serving frames taken with a different one.
  if (o.integration_time_register != 0) {
    camera->SetIntegrationTimeRegister(o.integration_time_register);
  }
  return camera;
}

TOFCAM_REGISTER_CAMERA_SOURCE("file", "file:<recording.h5>  play a tofcam recording",
                              OpenRecording);

}  // namespace
}  // namespace tofcam::cli

// Fuzzes RecordingReader: open, metadata, every frame (at most 64) and a PlaybackCamera pass.
// Any tofcam::Error is an accepted outcome; crashes, leaks, hangs and other exceptions are bugs.
#include <cstdint>

#include "fuzz_util.h"
#include "tofcam/core/error.h"
#include "tofcam/io/recording.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = tofcam::fuzz::WriteTemp(data, size, ".h5");
  try {
    tofcam::RecordingReader reader(path);
    const std::size_t n = reader.frame_count() < 64 ? reader.frame_count() : 64;
    for (std::size_t i = 0; i < n; ++i) {
      const tofcam::Frame frame = reader.Read(i);
      tofcam::ValidateFrame(frame);
    }
    if (reader.frame_count() > 0) {
      tofcam::PlaybackCamera camera(path);
      (void)camera.Grab();
    }
  } catch (const tofcam::Error&) {
  }
  return 0;
}

// Fuzzes the Azure Kinect calibration.json parser for each supported depth mode.
#include <cstdint>
#include <string_view>

#include "tofcam/core/error.h"
#include "tofcam/io/importers.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view json(reinterpret_cast<const char*>(data), size);
  constexpr int kSizes[][2] = {{640, 576}, {320, 288}, {512, 512}, {1024, 1024}};
  for (const auto& s : kSizes) {
    try {
      const tofcam::CameraIntrinsics k =
          tofcam::ParseAzureKinectCalibration(json, s[0], s[1], "fuzz.json");
      k.Validate();
    } catch (const tofcam::Error&) {
    }
  }
  return 0;
}

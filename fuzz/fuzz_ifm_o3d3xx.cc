// Fuzzes the ifm O3D3xx HDF5 importer.
#include <cstdint>

#include "fuzz_util.h"
#include "tofcam/core/error.h"
#include "tofcam/io/importers.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = tofcam::fuzz::WriteTemp(data, size, ".h5");
  try {
    const tofcam::ImportedSequence seq = tofcam::ImportIfmO3d3xx(path);
    for (const tofcam::Frame& f : seq.frames) tofcam::ValidateFrame(f);
    seq.camera.intrinsics.Validate();
  } catch (const tofcam::Error&) {
  }
  return 0;
}

// Fuzzes the MESA SwissRanger .dat text parser.
#include <cstdint>
#include <string_view>

#include "tofcam/core/error.h"
#include "tofcam/io/importers.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const tofcam::ImportedSequence seq = tofcam::ParseMesaDat(text, "fuzz.dat");
    for (const tofcam::Frame& f : seq.frames) tofcam::ValidateFrame(f);
    seq.camera.intrinsics.Validate();
  } catch (const tofcam::Error&) {
  }
  return 0;
}

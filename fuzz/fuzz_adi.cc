// Fuzzes the ADI ADTF3175 importers. The first two bytes choose the image size (1..64 each);
// the rest is the interleaved frame, and its two halves the raw depth and IR files.
#include <cstdint>
#include <string_view>

#include "fuzz_util.h"
#include "tofcam/core/error.h"
#include "tofcam/io/importers.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  const int width = 1 + data[0] % 64;
  const int height = 1 + data[1] % 64;
  const std::string_view body(reinterpret_cast<const char*>(data + 2), size - 2);
  try {
    const tofcam::ImportedSequence seq =
        tofcam::ParseAdiInterleaved(body, width, height, "fuzz.bin");
    tofcam::ValidateFrame(seq.frames.at(0));
  } catch (const tofcam::Error&) {
  }
  const std::size_t half = body.size() / 2;
  const auto depth = tofcam::fuzz::WriteTemp(data + 2, half, "_depth.bin");
  const auto ir = tofcam::fuzz::WriteTemp(data + 2 + half, body.size() - half, "_ir.bin");
  try {
    const tofcam::ImportedSequence seq = tofcam::ImportAdiRaw(depth, ir, width, height);
    tofcam::ValidateFrame(seq.frames.at(0));
  } catch (const tofcam::Error&) {
  }
  return 0;
}

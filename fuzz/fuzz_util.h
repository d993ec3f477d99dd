#pragma once
// Helpers for fuzzers whose parser reads a file by path (HDF5): the input goes to a per-process
// temporary file.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

namespace tofcam::fuzz {

inline std::filesystem::path WriteTemp(const std::uint8_t* data, std::size_t size,
                                       const char* suffix) {
  const std::filesystem::path path = std::filesystem::temp_directory_path() /
                                     ("tofcam_fuzz_" + std::to_string(::getpid()) + suffix);
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

}  // namespace tofcam::fuzz

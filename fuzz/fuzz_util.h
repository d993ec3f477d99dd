#pragma once
// Helpers for fuzzers whose parser reads a file by path (HDF5): the input goes to a per-process
// temporary file.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>

namespace tofcam::fuzz {

// One input in a per-process temporary file, removed when the object goes away: a fuzzer runs
// many inputs in one process and leaves no file behind when it exits.
class TempFile {
 public:
  TempFile(const std::uint8_t* data, std::size_t size, const char* suffix)
      : path_(std::filesystem::temp_directory_path() /
              ("tofcam_fuzz_" + std::to_string(::getpid()) + suffix)) {
    std::FILE* f = std::fopen(path_.c_str(), "wb");
    if (f == nullptr) std::abort();
    if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
    std::fclose(f);
  }
  ~TempFile() {
    std::error_code ignored;
    std::filesystem::remove(path_, ignored);
  }
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;
  // Implicit on purpose: the parsers take the path.
  operator const std::filesystem::path&() const { return path_; }

 private:
  std::filesystem::path path_;
};

inline TempFile WriteTemp(const std::uint8_t* data, std::size_t size, const char* suffix) {
  return TempFile(data, size, suffix);
}

}  // namespace tofcam::fuzz

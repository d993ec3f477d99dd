#pragma once
/// \file
/// Atomic file output: write to a temporary file beside the target, flush it to disk, then
/// rename over the target. A crash or an error leaves either the old file or the new one, never
/// a half-written one.

#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>

namespace tofcam {

/// Writes through a temporary `<path>.tmp-<pid>-<n>`; Commit() makes it `<path>`. If Commit() is
/// never called (error, exception) the destructor removes the temporary file. Throws
/// Error(kIo) naming the path when the file cannot be created, written or renamed.
class AtomicFile {
 public:
  explicit AtomicFile(std::filesystem::path path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  /// The open temporary file (binary mode), for C APIs such as libpng.
  [[nodiscard]] std::FILE* file() const noexcept { return file_; }
  void Write(std::string_view bytes);
  /// Flushes, fsyncs and renames onto the target path.
  void Commit();
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }

 private:
  std::filesystem::path path_;
  std::filesystem::path temp_path_;
  std::FILE* file_ = nullptr;
  bool committed_ = false;
};

/// Writes `bytes` to `path` atomically.
void WriteFileAtomically(const std::filesystem::path& path, std::string_view bytes);

/// Reads a whole file; throws Error(kNotFound) if missing, Error(kIo) if unreadable, and
/// Error(kFormat) if larger than `max_bytes`.
[[nodiscard]] std::string ReadFile(const std::filesystem::path& path,
                                   std::size_t max_bytes = std::size_t{1} << 30);

}  // namespace tofcam

#include "tofcam/core/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <system_error>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

std::atomic<unsigned> g_counter{0};

std::string Reason() { return std::strerror(errno); }

}  // namespace

AtomicFile::AtomicFile(std::filesystem::path path) : path_(std::move(path)) {
  // A new file or none: O_EXCL never follows a link someone placed at the temporary name (a
  // shared directory such as /tmp) and never writes into a file that is already there. A name
  // that exists (a link, or the leftover of a killed run whose pid this one reuses, as in a
  // container) is passed over for the next.
  int fd = -1;
  for (int attempt = 0; fd < 0; ++attempt) {
    temp_path_ = path_;
    temp_path_ += ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(g_counter++);
    fd = ::open(temp_path_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0 && (errno != EEXIST || attempt == 999)) {
      throw Error(ErrorCode::kIo, path_.string() + ": cannot create file: " + Reason());
    }
  }
  file_ = ::fdopen(fd, "wb");
  if (file_ == nullptr) {
    const std::string reason = Reason();
    ::close(fd);
    std::error_code ec;
    std::filesystem::remove(temp_path_, ec);
    throw Error(ErrorCode::kIo, path_.string() + ": cannot create file: " + reason);
  }
}

AtomicFile::~AtomicFile() {
  if (file_ != nullptr) std::fclose(file_);
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_path_, ec);
  }
}

void AtomicFile::Write(std::string_view bytes) {
  if (file_ == nullptr || std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size()) {
    throw Error(ErrorCode::kIo, path_.string() + ": write failed: " + Reason());
  }
}

void AtomicFile::Commit() {
  if (file_ == nullptr) throw Error(ErrorCode::kIo, path_.string() + ": already committed");
  const bool ok = std::fflush(file_) == 0 && ::fsync(::fileno(file_)) == 0;
  const int close_status = std::fclose(file_);
  file_ = nullptr;
  if (!ok || close_status != 0) {
    throw Error(ErrorCode::kIo, path_.string() + ": cannot flush file: " + Reason());
  }
  std::error_code ec;
  std::filesystem::rename(temp_path_, path_, ec);
  if (ec)
    throw Error(ErrorCode::kIo, path_.string() + ": cannot rename into place: " + ec.message());
  committed_ = true;
}

void WriteFileAtomically(const std::filesystem::path& path, std::string_view bytes) {
  AtomicFile f(path);
  f.Write(bytes);
  f.Commit();
}

std::string ReadFile(const std::filesystem::path& path, std::size_t max_bytes) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    throw Error(ErrorCode::kNotFound, path.string() + ": no such file");
  }
  if (std::filesystem::is_directory(path, ec)) {
    throw Error(ErrorCode::kIo, path.string() + ": is a directory, expected a file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorCode::kIo, path.string() + ": cannot open: " + Reason());
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) throw Error(ErrorCode::kIo, path.string() + ": cannot stat: " + ec.message());
  if (size > max_bytes) {
    throw Error(ErrorCode::kFormat, path.string() + ": file of " + std::to_string(size) +
                                        " bytes exceeds the limit of " + std::to_string(max_bytes));
  }
  std::string data(size, '\0');
  if (!in.read(data.data(), static_cast<std::streamsize>(size))) {
    throw Error(ErrorCode::kIo, path.string() + ": read failed");
  }
  return data;
}

}  // namespace tofcam

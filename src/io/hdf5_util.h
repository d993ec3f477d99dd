#pragma once
// Private helpers around the HDF5 C API: RAII handles, a guard that silences HDF5's own error
// printing, and checked reads that turn every HDF5 failure into a tofcam::Error naming the file.
// Not installed; used by recording.cc and the ifm importer.

#include <hdf5.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "tofcam/core/error.h"

namespace tofcam::io_internal {

/// Silences HDF5's automatic error-stack printing for its lifetime and restores the previous
/// handler afterwards (the library never prints).
class Hdf5Silencer {
 public:
  Hdf5Silencer() {
    H5Eget_auto2(H5E_DEFAULT, &old_func_, &old_data_);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~Hdf5Silencer() { H5Eset_auto2(H5E_DEFAULT, old_func_, old_data_); }
  Hdf5Silencer(const Hdf5Silencer&) = delete;
  Hdf5Silencer& operator=(const Hdf5Silencer&) = delete;

 private:
  H5E_auto2_t old_func_ = nullptr;
  void* old_data_ = nullptr;
};

/// Owns one hid_t and closes it with the matching H5?close.
class Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  Handle() = default;
  Handle(hid_t id, Closer closer) : id_(id), closer_(closer) {}
  ~Handle() { Reset(); }
  Handle(Handle&& o) noexcept : id_(o.id_), closer_(o.closer_) { o.id_ = H5I_INVALID_HID; }
  Handle& operator=(Handle&& o) noexcept {
    if (this != &o) {
      Reset();
      id_ = o.id_;
      closer_ = o.closer_;
      o.id_ = H5I_INVALID_HID;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;

  [[nodiscard]] hid_t get() const noexcept { return id_; }
  [[nodiscard]] bool valid() const noexcept { return id_ >= 0; }
  /// Closes now; returns false when HDF5 reports a failure.
  bool Reset() noexcept {
    bool ok = true;
    if (id_ >= 0 && closer_ != nullptr) ok = closer_(id_) >= 0;
    id_ = H5I_INVALID_HID;
    return ok;
  }

 private:
  hid_t id_ = H5I_INVALID_HID;
  Closer closer_ = nullptr;
};

/// Error helpers: "<file>: <what>".
[[noreturn]] void Fail(ErrorCode code, const std::filesystem::path& file, const std::string& what);

/// Opens an HDF5 file read-only. kNotFound if missing, kFormat if not HDF5.
[[nodiscard]] Handle OpenFileReadOnly(const std::filesystem::path& file);

/// True when `name` (a path relative to `loc`, may contain '/') exists as a link.
[[nodiscard]] bool Exists(hid_t loc, const std::string& name);

/// Opens a dataset; kFormat naming it when it is missing, virtual or stored outside the file,
/// filtered by anything but deflate and shuffle, or when its stored bytes cannot be what its
/// layout says (an unfiltered chunked dataset's storage must be whole chunks). Opened with the
/// chunk cache off, so that libhdf5 reads unfiltered chunks straight into the caller's buffer.
[[nodiscard]] Handle OpenDataset(const std::filesystem::path& file, hid_t loc,
                                 const std::string& name);

/// The dataset's dimensions; kFormat if it has more than `max_rank` dimensions.
[[nodiscard]] std::vector<hsize_t> DatasetDims(const std::filesystem::path& file, hid_t dataset,
                                               const std::string& name, int max_rank = 4);

/// Class and size of the dataset's stored type, checked: kFormat unless it is `cls` (H5T_INTEGER
/// or H5T_FLOAT) of `bytes` bytes with the given signedness (integers only).
void CheckType(const std::filesystem::path& file, hid_t dataset, const std::string& name,
               H5T_class_t cls, std::size_t bytes, bool is_signed = false);

/// Reads the hyperslab [start, start+count) of a dataset opened by OpenDataset into `out`
/// (prod(count) values of `mem_type`), converting from the stored type. Filtered chunked
/// datasets are decoded here, not by libhdf5: libhdf5 1.10 copies a chunk out of whatever its
/// filters returned without checking the size (a heap overflow on a damaged file, found by
/// fuzz_recording), so every chunk is read raw (H5Dread_chunk) and must inflate / unshuffle to
/// exactly one chunk. kFormat naming the dataset on any failure.
void ReadSelection(const std::filesystem::path& file, hid_t dataset, const std::string& name,
                   hid_t mem_type, const std::vector<hsize_t>& start,
                   const std::vector<hsize_t>& count, void* out);

/// ReadSelection into `out` (resized).
template <typename T>
void ReadSlab(const std::filesystem::path& file, hid_t dataset, const std::string& name,
              hid_t mem_type, const std::vector<hsize_t>& start, const std::vector<hsize_t>& count,
              std::vector<T>& out);

/// Longest string attribute (bytes, with its terminating NUL) the reader accepts and the writer
/// writes: a hostile file cannot make the reader allocate more.
inline constexpr std::size_t kMaxStringAttributeBytes = 1 << 16;

/// Reads a scalar attribute of `obj` (converted to `mem_type`); false when it does not exist,
/// kFormat when it exists but is not a scalar or one-element attribute of a convertible type.
bool ReadScalarAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                         hid_t mem_type, void* value);
/// Reads a numeric attribute of up to `max_elements` elements as doubles.
bool ReadDoubleArrayAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                              std::size_t max_elements, std::vector<double>& out);
/// Reads a string attribute (fixed or variable length, at most 64 KiB).
bool ReadStringAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                         std::string& out);

/// Writes (creating or replacing) a scalar attribute.
void WriteScalarAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                          hid_t type, const void* value);
void WriteDoubleArrayAttribute(const std::filesystem::path& file, hid_t obj,
                               const std::string& name, const std::vector<double>& values);
/// Writes a fixed-length, null-terminated ASCII string attribute (h5py reads it as bytes/str).
void WriteStringAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                          const std::string& value);

}  // namespace tofcam::io_internal

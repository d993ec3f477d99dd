#include "hdf5_util.h"

#include <algorithm>
#include <cstring>
#include <system_error>

namespace tofcam::io_internal {

void Fail(ErrorCode code, const std::filesystem::path& file, const std::string& what) {
  throw Error(code, file.string() + ": " + what);
}

Handle OpenFileReadOnly(const std::filesystem::path& file) {
  std::error_code ec;
  if (!std::filesystem::exists(file, ec)) Fail(ErrorCode::kNotFound, file, "no such file");
  if (!std::filesystem::is_regular_file(file, ec)) Fail(ErrorCode::kIo, file, "not a file");
  const htri_t is_hdf5 = H5Fis_hdf5(file.c_str());
  if (is_hdf5 <= 0) Fail(ErrorCode::kFormat, file, "not an HDF5 file");
  // "Strong" close releases every object still open in the file, so a reader that threw halfway
  // never keeps the file open.
  Handle fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
  if (!fapl.valid() || H5Pset_fclose_degree(fapl.get(), H5F_CLOSE_STRONG) < 0) {
    Fail(ErrorCode::kInternal, file, "cannot create HDF5 property list");
  }
  Handle f(H5Fopen(file.c_str(), H5F_ACC_RDONLY, fapl.get()), H5Fclose);
  if (!f.valid()) Fail(ErrorCode::kFormat, file, "cannot open as HDF5 (corrupted or truncated)");
  return f;
}

bool Exists(hid_t loc, const std::string& name) {
  // H5Lexists needs every intermediate group to exist; check the path component by component.
  std::size_t pos = 0;
  while (true) {
    const std::size_t slash = name.find('/', pos + 1);
    const std::string prefix = name.substr(0, slash);
    if (!prefix.empty() && prefix != "/") {
      if (H5Lexists(loc, prefix.c_str(), H5P_DEFAULT) <= 0) return false;
    }
    if (slash == std::string::npos) return true;
    pos = slash;
  }
}

Handle OpenDataset(const std::filesystem::path& file, hid_t loc, const std::string& name) {
  if (!Exists(loc, name)) Fail(ErrorCode::kFormat, file, "missing dataset '" + name + "'");
  Handle d(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!d.valid()) Fail(ErrorCode::kFormat, file, "'" + name + "' is not a readable dataset");
  // libhdf5 sizes its read and decompression buffers from the dataset's stored chunk sizes and
  // chunk shape. In a damaged file those can claim gigabytes (found by fuzz_recording), so both
  // are bounded before any read: stored bytes cannot exceed the file, and one chunk must fit a
  // sane buffer.
  constexpr hsize_t kMaxChunkBytes = hsize_t{1} << 28;
  hsize_t file_bytes = 0;
  const hid_t file_id = H5Iget_file_id(d.get());
  const bool have_size = file_id >= 0 && H5Fget_filesize(file_id, &file_bytes) >= 0;
  if (file_id >= 0) H5Fclose(file_id);
  if (!have_size) Fail(ErrorCode::kFormat, file, "cannot determine the file size");
  const hsize_t stored = H5Dget_storage_size(d.get());
  if (stored > file_bytes) {
    Fail(ErrorCode::kFormat, file,
         "dataset '" + name + "' claims " + std::to_string(stored) + " stored bytes in a file of " +
             std::to_string(file_bytes) + " (corrupted)");
  }
  Handle plist(H5Dget_create_plist(d.get()), H5Pclose);
  if (plist.valid() && H5Pget_layout(plist.get()) == H5D_CHUNKED) {
    hsize_t chunk[H5S_MAX_RANK] = {};
    const int rank = H5Pget_chunk(plist.get(), H5S_MAX_RANK, chunk);
    Handle type(H5Dget_type(d.get()), H5Tclose);
    const std::size_t element = type.valid() ? H5Tget_size(type.get()) : 0;
    if (rank <= 0 || element == 0) {
      Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has an unreadable chunk layout");
    }
    hsize_t bytes = element;
    for (int i = 0; i < rank; ++i) {
      if (chunk[i] == 0 || bytes > kMaxChunkBytes / chunk[i]) {
        Fail(ErrorCode::kFormat, file,
             "dataset '" + name + "' has a chunk larger than 256 MiB (corrupted?)");
      }
      bytes *= chunk[i];
    }
  }
  return d;
}

std::vector<hsize_t> DatasetDims(const std::filesystem::path& file, hid_t dataset,
                                 const std::string& name, int max_rank) {
  Handle space(H5Dget_space(dataset), H5Sclose);
  if (!space.valid()) Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has no dataspace");
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 0 || rank > max_rank) {
    Fail(ErrorCode::kFormat, file,
         "dataset '" + name + "' has rank " + std::to_string(rank) + " (at most " +
             std::to_string(max_rank) + " expected)");
  }
  std::vector<hsize_t> dims(static_cast<std::size_t>(rank));
  if (rank > 0 && H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr) < 0) {
    Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has unreadable dimensions");
  }
  return dims;
}

void CheckType(const std::filesystem::path& file, hid_t dataset, const std::string& name,
               H5T_class_t cls, std::size_t bytes, bool is_signed) {
  Handle type(H5Dget_type(dataset), H5Tclose);
  if (!type.valid()) Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has no type");
  const H5T_class_t actual = H5Tget_class(type.get());
  const std::size_t size = H5Tget_size(type.get());
  bool ok = actual == cls && size == bytes;
  if (ok && cls == H5T_INTEGER) ok = (H5Tget_sign(type.get()) == H5T_SGN_2) == is_signed;
  if (!ok) {
    const char* kind = cls == H5T_INTEGER ? (is_signed ? "int" : "uint") : "float";
    Fail(ErrorCode::kFormat, file,
         "dataset '" + name + "' has the wrong type (expected " + kind + std::to_string(bytes * 8) +
             ")");
  }
}

void CheckStoredChunks(const std::filesystem::path& file, hid_t dataset, const std::string& name,
                       const std::vector<hsize_t>& start, const std::vector<hsize_t>& count) {
  Handle plist(H5Dget_create_plist(dataset), H5Pclose);
  if (!plist.valid() || H5Pget_layout(plist.get()) != H5D_CHUNKED) return;
  if (H5Pget_nfilters(plist.get()) != 0) return;
  const int rank = static_cast<int>(start.size());
  std::vector<hsize_t> chunk(static_cast<std::size_t>(std::max(rank, 1)));
  Handle type(H5Dget_type(dataset), H5Tclose);
  const std::size_t element = type.valid() ? H5Tget_size(type.get()) : 0;
  if (count.size() != start.size() || H5Pget_chunk(plist.get(), rank, chunk.data()) != rank ||
      element == 0) {
    Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has an unreadable chunk layout");
  }
  hsize_t chunk_bytes = element;  // OpenDataset bounded it to 256 MiB
  for (hsize_t c : chunk) {
    if (c == 0) Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has an empty chunk");
    chunk_bytes *= c;
  }
  for (std::size_t k = 0; k < count.size(); ++k) {
    if (count[k] == 0) return;
  }
  // Every chunk the selection touches, as an odometer over the chunk grid; a read touches few.
  std::vector<hsize_t> first(start.size()), last(start.size()), at(start.size());
  for (std::size_t k = 0; k < start.size(); ++k) {
    first[k] = start[k] / chunk[k];
    last[k] = (start[k] + count[k] - 1) / chunk[k];
    at[k] = first[k];
  }
  std::vector<hsize_t> offset(start.size());
  while (true) {
    for (std::size_t k = 0; k < at.size(); ++k) offset[k] = at[k] * chunk[k];
    unsigned mask = 0;
    haddr_t address = HADDR_UNDEF;
    hsize_t stored = 0;
    if (H5Dget_chunk_info_by_coord(dataset, offset.data(), &mask, &address, &stored) < 0) {
      Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has an unreadable chunk index");
    }
    if (address != HADDR_UNDEF && stored != chunk_bytes) {
      Fail(ErrorCode::kFormat, file,
           "dataset '" + name + "' stores a chunk of " + std::to_string(stored) + " bytes, " +
               std::to_string(chunk_bytes) + " expected (corrupted)");
    }
    std::size_t k = at.size();
    while (k-- > 0) {
      if (++at[k] <= last[k]) break;
      at[k] = first[k];
    }
    if (k == static_cast<std::size_t>(-1)) return;
  }
}

template <typename T>
void ReadSlab(const std::filesystem::path& file, hid_t dataset, const std::string& name,
              hid_t mem_type, const std::vector<hsize_t>& start, const std::vector<hsize_t>& count,
              std::vector<T>& out) {
  std::size_t n = 1;
  for (hsize_t c : count) n *= static_cast<std::size_t>(c);
  out.resize(n);
  Handle file_space(H5Dget_space(dataset), H5Sclose);
  if (!file_space.valid() || H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start.data(),
                                                 nullptr, count.data(), nullptr) < 0) {
    Fail(ErrorCode::kFormat, file, "cannot select frames of dataset '" + name + "'");
  }
  CheckStoredChunks(file, dataset, name, start, count);
  Handle mem_space(H5Screate_simple(static_cast<int>(count.size()), count.data(), nullptr),
                   H5Sclose);
  if (!mem_space.valid() ||
      H5Dread(dataset, mem_type, mem_space.get(), file_space.get(), H5P_DEFAULT, out.data()) < 0) {
    Fail(ErrorCode::kFormat, file, "cannot read dataset '" + name + "' (corrupted data?)");
  }
}

template void ReadSlab<std::uint8_t>(const std::filesystem::path&, hid_t, const std::string&, hid_t,
                                     const std::vector<hsize_t>&, const std::vector<hsize_t>&,
                                     std::vector<std::uint8_t>&);
template void ReadSlab<std::uint16_t>(const std::filesystem::path&, hid_t, const std::string&,
                                      hid_t, const std::vector<hsize_t>&,
                                      const std::vector<hsize_t>&, std::vector<std::uint16_t>&);
template void ReadSlab<std::int16_t>(const std::filesystem::path&, hid_t, const std::string&, hid_t,
                                     const std::vector<hsize_t>&, const std::vector<hsize_t>&,
                                     std::vector<std::int16_t>&);
template void ReadSlab<std::int32_t>(const std::filesystem::path&, hid_t, const std::string&, hid_t,
                                     const std::vector<hsize_t>&, const std::vector<hsize_t>&,
                                     std::vector<std::int32_t>&);
template void ReadSlab<std::int64_t>(const std::filesystem::path&, hid_t, const std::string&, hid_t,
                                     const std::vector<hsize_t>&, const std::vector<hsize_t>&,
                                     std::vector<std::int64_t>&);
template void ReadSlab<std::uint64_t>(const std::filesystem::path&, hid_t, const std::string&,
                                      hid_t, const std::vector<hsize_t>&,
                                      const std::vector<hsize_t>&, std::vector<std::uint64_t>&);
template void ReadSlab<float>(const std::filesystem::path&, hid_t, const std::string&, hid_t,
                              const std::vector<hsize_t>&, const std::vector<hsize_t>&,
                              std::vector<float>&);
template void ReadSlab<double>(const std::filesystem::path&, hid_t, const std::string&, hid_t,
                               const std::vector<hsize_t>&, const std::vector<hsize_t>&,
                               std::vector<double>&);

namespace {

Handle OpenAttribute(hid_t obj, const std::string& name) {
  if (H5Aexists(obj, name.c_str()) <= 0) return {};
  return {H5Aopen(obj, name.c_str(), H5P_DEFAULT), H5Aclose};
}

hssize_t AttributeElements(const std::filesystem::path& file, hid_t attr, const std::string& name) {
  Handle space(H5Aget_space(attr), H5Sclose);
  const hssize_t n = space.valid() ? H5Sget_simple_extent_npoints(space.get()) : -1;
  if (n < 0) Fail(ErrorCode::kFormat, file, "attribute '" + name + "' has no dataspace");
  return n;
}

}  // namespace

bool ReadScalarAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                         hid_t mem_type, void* value) {
  Handle attr = OpenAttribute(obj, name);
  if (!attr.valid()) return false;
  if (AttributeElements(file, attr.get(), name) != 1) {
    Fail(ErrorCode::kFormat, file, "attribute '" + name + "' is not a single value");
  }
  Handle type(H5Aget_type(attr.get()), H5Tclose);
  const H5T_class_t cls = type.valid() ? H5Tget_class(type.get()) : H5T_NO_CLASS;
  if (cls != H5T_INTEGER && cls != H5T_FLOAT) {
    Fail(ErrorCode::kFormat, file, "attribute '" + name + "' is not numeric");
  }
  if (H5Aread(attr.get(), mem_type, value) < 0) {
    Fail(ErrorCode::kFormat, file, "cannot read attribute '" + name + "'");
  }
  return true;
}

bool ReadDoubleArrayAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                              std::size_t max_elements, std::vector<double>& out) {
  Handle attr = OpenAttribute(obj, name);
  if (!attr.valid()) return false;
  const hssize_t n = AttributeElements(file, attr.get(), name);
  if (static_cast<std::size_t>(n) > max_elements) {
    Fail(ErrorCode::kFormat, file, "attribute '" + name + "' has too many elements");
  }
  Handle type(H5Aget_type(attr.get()), H5Tclose);
  const H5T_class_t cls = type.valid() ? H5Tget_class(type.get()) : H5T_NO_CLASS;
  if (cls != H5T_INTEGER && cls != H5T_FLOAT) {
    Fail(ErrorCode::kFormat, file, "attribute '" + name + "' is not numeric");
  }
  out.assign(static_cast<std::size_t>(n), 0.0);
  if (n > 0 && H5Aread(attr.get(), H5T_NATIVE_DOUBLE, out.data()) < 0) {
    Fail(ErrorCode::kFormat, file, "cannot read attribute '" + name + "'");
  }
  return true;
}

bool ReadStringAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                         std::string& out) {
  constexpr std::size_t kMaxBytes = 1 << 16;
  Handle attr = OpenAttribute(obj, name);
  if (!attr.valid()) return false;
  if (AttributeElements(file, attr.get(), name) != 1) {
    Fail(ErrorCode::kFormat, file, "attribute '" + name + "' is not a single string");
  }
  Handle type(H5Aget_type(attr.get()), H5Tclose);
  if (!type.valid() || H5Tget_class(type.get()) != H5T_STRING) {
    Fail(ErrorCode::kFormat, file, "attribute '" + name + "' is not a string");
  }
  if (H5Tis_variable_str(type.get()) > 0) {
    Handle mem(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(mem.get(), H5T_VARIABLE);
    char* value = nullptr;
    if (H5Aread(attr.get(), mem.get(), &value) < 0) {
      Fail(ErrorCode::kFormat, file, "cannot read string attribute '" + name + "'");
    }
    out = value == nullptr ? std::string() : std::string(value, strnlen(value, kMaxBytes));
    if (value != nullptr) H5free_memory(value);
    return true;
  }
  const std::size_t size = H5Tget_size(type.get());
  if (size == 0 || size > kMaxBytes) {
    Fail(ErrorCode::kFormat, file, "string attribute '" + name + "' has a hostile length");
  }
  Handle mem(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(mem.get(), size);
  H5Tset_strpad(mem.get(), H5T_STR_NULLPAD);
  std::string buffer(size, '\0');
  if (H5Aread(attr.get(), mem.get(), buffer.data()) < 0) {
    Fail(ErrorCode::kFormat, file, "cannot read string attribute '" + name + "'");
  }
  out.assign(buffer.c_str(), strnlen(buffer.c_str(), size));
  return true;
}

void WriteScalarAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                          hid_t type, const void* value) {
  if (H5Aexists(obj, name.c_str()) > 0) H5Adelete(obj, name.c_str());
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  Handle attr(H5Acreate2(obj, name.c_str(), type, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.valid() || H5Awrite(attr.get(), type, value) < 0) {
    Fail(ErrorCode::kIo, file, "cannot write attribute '" + name + "'");
  }
}

void WriteDoubleArrayAttribute(const std::filesystem::path& file, hid_t obj,
                               const std::string& name, const std::vector<double>& values) {
  if (H5Aexists(obj, name.c_str()) > 0) H5Adelete(obj, name.c_str());
  const hsize_t n = values.size();
  Handle space(H5Screate_simple(1, &n, nullptr), H5Sclose);
  Handle attr(H5Acreate2(obj, name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT),
              H5Aclose);
  if (!attr.valid() || H5Awrite(attr.get(), H5T_NATIVE_DOUBLE, values.data()) < 0) {
    Fail(ErrorCode::kIo, file, "cannot write attribute '" + name + "'");
  }
}

void WriteStringAttribute(const std::filesystem::path& file, hid_t obj, const std::string& name,
                          const std::string& value) {
  if (H5Aexists(obj, name.c_str()) > 0) H5Adelete(obj, name.c_str());
  Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(type.get(), value.size() + 1);
  H5Tset_strpad(type.get(), H5T_STR_NULLTERM);
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  Handle attr(H5Acreate2(obj, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT),
              H5Aclose);
  if (!attr.valid() || H5Awrite(attr.get(), type.get(), value.c_str()) < 0) {
    Fail(ErrorCode::kIo, file, "cannot write attribute '" + name + "'");
  }
}

}  // namespace tofcam::io_internal

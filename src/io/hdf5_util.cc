#include "hdf5_util.h"

#include <zlib.h>

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
  // No chunk cache: libhdf5 then reads an unfiltered chunk straight into the caller's buffer at
  // the layout's size instead of copying it out of a buffer sized by the (possibly damaged)
  // chunk index. Filtered chunks never reach libhdf5's filters (ReadSelection).
  Handle dapl(H5Pcreate(H5P_DATASET_ACCESS), H5Pclose);
  if (!dapl.valid() || H5Pset_chunk_cache(dapl.get(), H5D_CHUNK_CACHE_NSLOTS_DEFAULT, 0,
                                          H5D_CHUNK_CACHE_W0_DEFAULT) < 0) {
    Fail(ErrorCode::kInternal, file, "cannot create HDF5 dataset access property list");
  }
  Handle d(H5Dopen2(loc, name.c_str(), dapl.get()), H5Dclose);
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
  const H5D_layout_t layout = plist.valid() ? H5Pget_layout(plist.get()) : H5D_LAYOUT_ERROR;
  if (layout == H5D_LAYOUT_ERROR) {
    Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has an unreadable layout");
  }
  // A virtual dataset or external storage would make libhdf5 open files the damaged file names.
  if (layout == H5D_VIRTUAL || H5Pget_external_count(plist.get()) != 0) {
    Fail(ErrorCode::kFormat, file,
         "dataset '" + name + "' is virtual or stored in other files (not read by tofcam)");
  }
  if (layout == H5D_COMPACT || layout == H5D_CONTIGUOUS) {
    // libhdf5 1.10 copies a compact dataset out of the bytes its header stores without checking
    // them against the dataspace (a heap over-read on a damaged file, found in review); a
    // contiguous one is read from the file, bounded by its end, but must still be whole.
    Handle type(H5Dget_type(d.get()), H5Tclose);
    Handle space(H5Dget_space(d.get()), H5Sclose);
    const std::size_t element = type.valid() ? H5Tget_size(type.get()) : 0;
    const hssize_t points = space.valid() ? H5Sget_simple_extent_npoints(space.get()) : -1;
    if (element == 0 || points < 0) {
      Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has an unreadable type or extent");
    }
    const hsize_t needed = static_cast<hsize_t>(points) * element;
    if (stored != needed && (layout == H5D_COMPACT || stored != 0)) {
      Fail(ErrorCode::kFormat, file,
           "dataset '" + name + "' stores " + std::to_string(stored) + " bytes for " +
               std::to_string(points) + " values of " + std::to_string(element) +
               " bytes (corrupted)");
    }
  }
  if (layout == H5D_CHUNKED) {
    const int filters = H5Pget_nfilters(plist.get());
    if (filters < 0)
      Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has unreadable filters");
    for (int k = 0; k < filters; ++k) {
      unsigned flags = 0;
      std::size_t n = 0;
      const H5Z_filter_t id = H5Pget_filter2(plist.get(), static_cast<unsigned>(k), &flags, &n,
                                             nullptr, 0, nullptr, nullptr);
      if (id != H5Z_FILTER_DEFLATE && id != H5Z_FILTER_SHUFFLE) {
        Fail(ErrorCode::kFormat, file,
             "dataset '" + name + "' uses HDF5 filter " + std::to_string(id) +
                 " (tofcam reads deflate and shuffle)");
      }
    }
  }
  if (layout == H5D_CHUNKED) {
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
    // Unfiltered chunks are stored whole (edge chunks too). H5Dget_num_chunks would say how many,
    // but it reports 0 for some chunk indexes of libhdf5 1.10.8.
    if (H5Pget_nfilters(plist.get()) == 0 && stored % bytes != 0) {
      Fail(ErrorCode::kFormat, file,
           "dataset '" + name + "' stores " + std::to_string(stored) +
               " bytes, not a whole number of " + std::to_string(bytes) +
               "-byte chunks (corrupted)");
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

namespace {

// Inflates `in` into exactly `expected` bytes; false for anything else (a damaged stream, or one
// that inflates to more or fewer bytes than a chunk).
bool Inflate(const std::vector<unsigned char>& in, std::size_t expected,
             std::vector<unsigned char>& out) {
  out.resize(expected);
  z_stream z{};
  if (inflateInit(&z) != Z_OK) return false;
  z.next_in = const_cast<unsigned char*>(in.data());
  z.avail_in = static_cast<uInt>(in.size());
  z.next_out = out.data();
  z.avail_out = static_cast<uInt>(expected);
  const int rc = inflate(&z, Z_FINISH);
  const bool ok = rc == Z_STREAM_END && z.total_out == expected;
  inflateEnd(&z);
  return ok;
}

// Element sizes known at compile time let GCC vectorise the interleaving stores.
template <std::size_t kSize>
void UnshuffleFixed(const unsigned char* __restrict in, std::size_t n,
                    unsigned char* __restrict out) {
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t k = 0; k < kSize; ++k) out[i * kSize + k] = in[k * n + i];
  }
}

// HDF5's shuffle stores byte k of every element together; this puts them back.
void Unshuffle(const std::vector<unsigned char>& in, std::size_t element,
               std::vector<unsigned char>& out) {
  out.resize(in.size());
  const std::size_t n = in.size() / element;
  if (element == 2) {
    UnshuffleFixed<2>(in.data(), n, out.data());
  } else if (element == 4) {
    UnshuffleFixed<4>(in.data(), n, out.data());
  } else if (element == 8) {
    UnshuffleFixed<8>(in.data(), n, out.data());
  } else {
    for (std::size_t k = 0; k < element; ++k) {
      for (std::size_t i = 0; i < n; ++i) out[i * element + k] = in[k * n + i];
    }
  }
  // Bytes past the last whole element are stored as they are (HDF5's rule).
  std::copy(in.begin() + static_cast<std::ptrdiff_t>(n * element), in.end(),
            out.begin() + static_cast<std::ptrdiff_t>(n * element));
}

std::string Coordinates(const std::vector<hsize_t>& v) {
  std::string s = "(";
  for (std::size_t k = 0; k < v.size(); ++k) s += (k ? ", " : "") + std::to_string(v[k]);
  return s + ")";
}

void ReadFilteredChunks(const std::filesystem::path& file, hid_t dataset, hid_t plist,
                        const std::string& name, hid_t mem_type, const std::vector<hsize_t>& start,
                        const std::vector<hsize_t>& count, unsigned char* out) {
  const auto bad = [&](const std::string& what) {
    Fail(ErrorCode::kFormat, file, "dataset '" + name + "' " + what);
  };
  const std::size_t rank = start.size();
  std::vector<hsize_t> chunk(rank);
  Handle file_type(H5Dget_type(dataset), H5Tclose);
  const std::size_t file_size = file_type.valid() ? H5Tget_size(file_type.get()) : 0;
  const std::size_t mem_size = H5Tget_size(mem_type);
  if (rank == 0 ||
      H5Pget_chunk(plist, static_cast<int>(rank), chunk.data()) != static_cast<int>(rank) ||
      file_size == 0 || mem_size == 0) {
    bad("has an unreadable chunk layout or type");
  }
  const std::vector<hsize_t> dims = DatasetDims(file, dataset, name, static_cast<int>(rank));
  if (dims.size() != rank) bad("has rank " + std::to_string(dims.size()));
  for (std::size_t k = 0; k < rank; ++k) {
    if (count[k] == 0) return;
    if (start[k] > dims[k] || count[k] > dims[k] - start[k]) bad("is smaller than the read");
  }
  hsize_t chunk_elements = 1;
  for (hsize_t c : chunk) chunk_elements *= c;  // OpenDataset bounded it to 256 MiB
  const std::size_t chunk_bytes = static_cast<std::size_t>(chunk_elements) * file_size;
  const int filters = H5Pget_nfilters(plist);
  std::vector<H5Z_filter_t> ids;
  std::vector<std::size_t> shuffle_size;
  for (int k = 0; k < filters; ++k) {
    unsigned flags = 0, cd[4] = {};
    std::size_t n = 4;
    ids.push_back(
        H5Pget_filter2(plist, static_cast<unsigned>(k), &flags, &n, cd, 0, nullptr, nullptr));
    shuffle_size.push_back(n > 0 && cd[0] > 0 ? cd[0] : file_size);
  }
  // Deflate never stores more than compressBound of its input; a chunk with its filters skipped
  // is stored whole. Larger claims are damage, refused before any buffer is sized by them.
  const hsize_t max_stored = compressBound(static_cast<uLong>(chunk_bytes));
  const bool convert = H5Tequal(file_type.get(), mem_type) <= 0;
  unsigned chunk_options = 0;
  const bool raw_partial_chunks = H5Pget_chunk_opts(plist, &chunk_options) >= 0 &&
                                  (chunk_options & H5D_CHUNK_DONT_FILTER_PARTIAL_CHUNKS) != 0;
  // Conversion runs through a buffer of one run (not the whole chunk: a tiny file with a huge
  // chunk of bytes read as doubles would otherwise ask for 8x the chunk).
  std::vector<unsigned char> converted;
  std::vector<unsigned char> fill;  // the fill value in mem_type, fetched at the first need

  thread_local std::vector<unsigned char> a, b;
  // Kept between calls (no allocation per frame), but not a damaged file's huge chunk.
  struct Shrink {
    ~Shrink() {
      constexpr std::size_t kKeep = std::size_t{64} << 20;
      if (a.capacity() > kKeep) std::vector<unsigned char>().swap(a);
      if (b.capacity() > kKeep) std::vector<unsigned char>().swap(b);
    }
  } shrink;
  std::vector<hsize_t> first(rank), last(rank), at(rank), offset(rank), lo(rank), hi(rank);
  for (std::size_t k = 0; k < rank; ++k) {
    first[k] = start[k] / chunk[k];
    last[k] = (start[k] + count[k] - 1) / chunk[k];
    at[k] = first[k];
  }
  while (true) {
    for (std::size_t k = 0; k < rank; ++k) {
      offset[k] = at[k] * chunk[k];
      lo[k] = std::max(start[k], offset[k]);
      hi[k] = std::min(start[k] + count[k], offset[k] + chunk[k]);
    }
    hsize_t stored = 0;
    if (H5Dget_chunk_storage_size(dataset, offset.data(), &stored) < 0) {
      // libhdf5 1.10 fails this for chunks never written as well as for a damaged index; the
      // slower lookup tells them apart (an undefined address: not written, the fill value).
      unsigned mask = 0;
      haddr_t address = HADDR_UNDEF;
      if (H5Dget_chunk_info_by_coord(dataset, offset.data(), &mask, &address, &stored) < 0 ||
          address != HADDR_UNDEF) {
        bad("has an unreadable chunk index at " + Coordinates(offset) + " (corrupted)");
      }
      stored = 0;
    }
    const unsigned char* values = nullptr;  // the chunk in mem_type, or null: fill value
    if (stored > 0) {
      if (stored > max_stored) {
        bad("claims a chunk of " + std::to_string(stored) + " stored bytes at " +
            Coordinates(offset) + " (corrupted)");
      }
      a.resize(static_cast<std::size_t>(stored));
      std::uint32_t mask = 0;
      if (H5Dread_chunk(dataset, H5P_DEFAULT, offset.data(), &mask, a.data()) < 0) {
        bad("has an unreadable chunk at " + Coordinates(offset));
      }
      // With H5D_CHUNK_DONT_FILTER_PARTIAL_CHUNKS libhdf5 stores chunks that reach past the
      // extent raw, with mask 0.
      bool partial = false;
      for (std::size_t k = 0; k < rank; ++k) partial |= offset[k] + chunk[k] > dims[k];
      if (partial && raw_partial_chunks) mask = ~0u;
      for (int k = filters - 1; k >= 0; --k) {
        if (mask >> k & 1u) continue;  // this filter was not applied to this chunk
        if (ids[static_cast<std::size_t>(k)] == H5Z_FILTER_DEFLATE) {
          if (!Inflate(a, chunk_bytes, b)) {
            bad("has a chunk at " + Coordinates(offset) + " that does not inflate to " +
                std::to_string(chunk_bytes) + " bytes (corrupted)");
          }
        } else {
          if (a.size() != chunk_bytes) break;  // reported below
          Unshuffle(a, shuffle_size[static_cast<std::size_t>(k)], b);
        }
        std::swap(a, b);
      }
      if (a.size() != chunk_bytes) {
        bad("has a chunk at " + Coordinates(offset) + " of " + std::to_string(a.size()) +
            " bytes, " + std::to_string(chunk_bytes) + " expected (corrupted)");
      }
      values = a.data();
    }
    if (!values && fill.empty()) {
      // Unallocated chunks read as the fill value (0 unless the file defines one).
      fill.assign(mem_size, 0);
      if (H5Pget_fill_value(plist, mem_type, fill.data()) < 0)
        std::fill(fill.begin(), fill.end(), 0);
    }
    // Copy the chunk's part of the selection, one run along the last dimension at a time.
    std::vector<hsize_t> i = lo;
    const std::size_t run = static_cast<std::size_t>(hi[rank - 1] - lo[rank - 1]);
    while (true) {
      std::size_t src = 0, dst = 0;
      for (std::size_t k = 0; k < rank; ++k) {
        src = src * chunk[k] + (i[k] - offset[k]);
        dst = dst * count[k] + (i[k] - start[k]);
      }
      unsigned char* to = out + dst * mem_size;
      if (values && convert) {
        converted.resize(run * std::max(file_size, mem_size));
        std::memcpy(converted.data(), values + src * file_size, run * file_size);
        if (H5Tconvert(file_type.get(), mem_type, run, converted.data(), nullptr, H5P_DEFAULT) <
            0) {
          bad("has values that do not convert to the requested type");
        }
        std::memcpy(to, converted.data(), run * mem_size);
      } else if (values) {
        std::memcpy(to, values + src * mem_size, run * mem_size);
      } else {
        for (std::size_t e = 0; e < run; ++e) std::memcpy(to + e * mem_size, fill.data(), mem_size);
      }
      std::size_t k = rank - 1;
      while (k-- > 0) {
        if (++i[k] < hi[k]) break;
        i[k] = lo[k];
      }
      if (k == static_cast<std::size_t>(-1)) break;
    }
    std::size_t k = rank;
    while (k-- > 0) {
      if (++at[k] <= last[k]) break;
      at[k] = first[k];
    }
    if (k == static_cast<std::size_t>(-1)) return;
  }
}

}  // namespace

void ReadSelection(const std::filesystem::path& file, hid_t dataset, const std::string& name,
                   hid_t mem_type, const std::vector<hsize_t>& start,
                   const std::vector<hsize_t>& count, void* out) {
  if (start.size() != count.size()) {
    Fail(ErrorCode::kInternal, file, "read of dataset '" + name + "' with a malformed selection");
  }
  Handle plist(H5Dget_create_plist(dataset), H5Pclose);
  if (!plist.valid()) Fail(ErrorCode::kFormat, file, "dataset '" + name + "' has no layout");
  // Numbers only: conversions of compound, string or variable-length types would need a
  // background buffer and read memory the file points to.
  Handle type(H5Dget_type(dataset), H5Tclose);
  const H5T_class_t cls = type.valid() ? H5Tget_class(type.get()) : H5T_NO_CLASS;
  if (cls != H5T_INTEGER && cls != H5T_FLOAT) {
    Fail(ErrorCode::kFormat, file, "dataset '" + name + "' does not hold numbers");
  }
  if (H5Pget_layout(plist.get()) == H5D_CHUNKED && H5Pget_nfilters(plist.get()) > 0) {
    ReadFilteredChunks(file, dataset, plist.get(), name, mem_type, start, count,
                       static_cast<unsigned char*>(out));
    return;
  }
  Handle file_space(H5Dget_space(dataset), H5Sclose);
  if (!file_space.valid() || H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start.data(),
                                                 nullptr, count.data(), nullptr) < 0) {
    Fail(ErrorCode::kFormat, file, "cannot select frames of dataset '" + name + "'");
  }
  Handle mem_space(H5Screate_simple(static_cast<int>(count.size()), count.data(), nullptr),
                   H5Sclose);
  if (!mem_space.valid() ||
      H5Dread(dataset, mem_type, mem_space.get(), file_space.get(), H5P_DEFAULT, out) < 0) {
    Fail(ErrorCode::kFormat, file, "cannot read dataset '" + name + "' (corrupted data?)");
  }
}

template <typename T>
void ReadSlab(const std::filesystem::path& file, hid_t dataset, const std::string& name,
              hid_t mem_type, const std::vector<hsize_t>& start, const std::vector<hsize_t>& count,
              std::vector<T>& out) {
  std::size_t n = 1;
  for (hsize_t c : count) n *= static_cast<std::size_t>(c);
  if (H5Tget_size(mem_type) != sizeof(T)) {
    Fail(ErrorCode::kInternal, file, "read of dataset '" + name + "' into a wrong-sized type");
  }
  out.resize(n);
  ReadSelection(file, dataset, name, mem_type, start, count, out.data());
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
  constexpr std::size_t kMaxBytes = kMaxStringAttributeBytes;
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
  if (value.size() + 1 > kMaxStringAttributeBytes) {
    // The reader would refuse the file (ReadStringAttribute): refuse to write it.
    Fail(ErrorCode::kInvalidArgument, file,
         "attribute '" + name + "' is " + std::to_string(value.size()) + " bytes, more than the " +
             std::to_string(kMaxStringAttributeBytes - 1) + " a recording may hold");
  }
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

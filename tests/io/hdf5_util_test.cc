// The private HDF5 helpers against hostile files that the public readers cannot be given
// directly (tofcam recordings are checksummed; these use HDF5's old, unchecksummed format, as
// third-party files such as the ifm exports do). Found in review on November 25; the overflows
// they guard against show under ASan (`make test-sanitize`), the refusals in every build.

#include "hdf5_util.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "tofcam/core/error.h"

namespace tofcam::io_internal {
namespace {

namespace fs = std::filesystem;

fs::path TempFile(const std::string& name) {
  return fs::temp_directory_path() /
         ("tofcam_hdf5_util_test_" + std::to_string(::getpid()) + "_" + name);
}

// A compact dataset of 16 bytes whose dataspace is then patched to claim 4112 values: libhdf5
// 1.10 opens it and H5Dread copied 4112 bytes out of the 16 (heap over-read). OpenDataset must
// refuse it, naming the sizes.
TEST(Hdf5Util, CompactDataShorterThanItsExtentIsRefused) {
  const fs::path p = TempFile("compact.h5");
  {
    const hid_t f = H5Fcreate(p.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    const hsize_t dims = 16;
    const hid_t space = H5Screate_simple(1, &dims, nullptr);
    const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_layout(dcpl, H5D_COMPACT);
    const hid_t d = H5Dcreate2(f, "c", H5T_STD_U8LE, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
    unsigned char v[16];
    std::memset(v, 9, sizeof v);
    ASSERT_GE(H5Dwrite(d, H5T_NATIVE_UINT8, H5S_ALL, H5S_ALL, H5P_DEFAULT, v), 0);
    H5Dclose(d);
    H5Pclose(dcpl);
    H5Sclose(space);
    H5Fclose(f);
  }
  {
    // The version-1 dataspace message: version 1, rank 1, flags (1: maximum dimensions
    // follow), 5 reserved bytes, the dimension 16 as 8 little-endian bytes (and the maximum, 16).
    // Their second bytes become 0x10: 16 + 4096 = 4112.
    std::ifstream in(p, std::ios::binary);
    std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
    in.close();
    const unsigned char pattern[16] = {1, 1, 1, 0, 0, 0, 0, 0, 16, 0, 0, 0, 0, 0, 0, 0};
    int hits = 0;
    for (std::size_t i = 0; i + 24 <= bytes.size(); ++i) {
      if (std::memcmp(&bytes[i], pattern, 16) == 0 && bytes[i + 16] == 16) {
        bytes[i + 9] = 0x10;
        bytes[i + 17] = 0x10;
        ++hits;
      }
    }
    ASSERT_EQ(hits, 1) << "the dataspace message was not found where HDF5 1.10 writes it";
    std::ofstream(p, std::ios::binary)
        .write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }
  Hdf5Silencer quiet;
  const Handle f = OpenFileReadOnly(p);
  try {
    const Handle d = OpenDataset(p, f.get(), "c");
    std::vector<std::uint8_t> out;
    ReadSlab(p, d.get(), "c", H5T_NATIVE_UINT8, {0}, {4112}, out);
    ADD_FAILURE() << "16 stored bytes were read as 4112 values";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFormat);
    EXPECT_NE(std::string(e.what()).find("'c' stores 16 bytes for 4112 values"), std::string::npos)
        << e.what();
  }
  fs::remove(p);
}

// Unfiltered chunks of 16 bytes stored as 8, 24, 16 and 16 (a whole number of chunks in all, so
// the storage check passes): libhdf5's chunk cache copied 16 bytes out of the 8-byte buffer.
// With the cache off (OpenDataset) libhdf5 reads each chunk from the file at the layout's size:
// the values may be wrong (the file is damaged) but nothing is read out of bounds (ASan) and the
// chunks stored whole read right.
TEST(Hdf5Util, UnfilteredChunksStoredShortAreReadFromTheFile) {
  const fs::path p = TempFile("short.h5");
  {
    const hid_t f = H5Fcreate(p.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    const hsize_t dims = 64, chunk = 16, max_dims = H5S_UNLIMITED;
    const hid_t space = H5Screate_simple(1, &dims, &max_dims);
    const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_chunk(dcpl, 1, &chunk);
    const hid_t d = H5Dcreate2(f, "u8", H5T_STD_U8LE, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
    const std::size_t sizes[4] = {8, 24, 16, 16};
    for (hsize_t k = 0; k < 4; ++k) {
      const std::vector<unsigned char> b(sizes[k], static_cast<unsigned char>(k + 1));
      const hsize_t offset = k * 16;
      ASSERT_GE(H5Dwrite_chunk(d, H5P_DEFAULT, 0, &offset, b.size(), b.data()), 0);
    }
    H5Dclose(d);
    H5Pclose(dcpl);
    H5Sclose(space);
    H5Fclose(f);
  }
  Hdf5Silencer quiet;
  const Handle f = OpenFileReadOnly(p);
  const Handle d = OpenDataset(p, f.get(), "u8");
  std::vector<std::uint16_t> out;  // converted: libhdf5's conversion path too
  try {
    ReadSlab(p, d.get(), "u8", H5T_NATIVE_UINT16, {0}, {64}, out);
    ASSERT_EQ(out.size(), 64u);
    for (std::size_t i = 48; i < 64; ++i) EXPECT_EQ(out[i], 4) << i;  // the last chunk is whole
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFormat) << e.what();  // refusing is as good
  }
  fs::remove(p);
}

}  // namespace
}  // namespace tofcam::io_internal

// Writes small, valid seed inputs for every fuzzer into <corpus dir>/<fuzzer>/.
// Usage: fuzz_seed_writer <corpus dir> <source dir>
#include <hdf5.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/io/recording.h"

namespace fs = std::filesystem;
using namespace tofcam;

namespace {

void WriteRecordingSeed(const fs::path& file, int compression, bool extras) {
  CameraInfo cam;
  cam.model = "seed";
  cam.intrinsics.width = 6;
  cam.intrinsics.height = 4;
  cam.intrinsics.cx_px = 2.5;
  cam.intrinsics.cy_px = 1.5;
  RecordingOptions options;
  options.compression_level = compression;
  RecordingWriter writer(file, cam, options);
  for (int i = 0; i < 2; ++i) {
    Frame f;
    f.distance = Image<std::uint16_t>(6, 4, static_cast<std::uint16_t>(1000 * (i + 1)));
    f.amplitude = Image<std::uint16_t>(6, 4, 500);
    f.intensity = Image<std::uint16_t>(6, 4, 900);
    if (extras) {
      f.source_flags = Image<PixelFlags>(6, 4, PixelFlags(Flag::kSaturated));
      GroundTruth t;
      t.radial_distance_m = Image<float>(6, 4, 1.5f);
      t.causes = Image<PixelFlags>(6, 4);
      t.sigma_m = Image<float>(6, 4, 0.01f);
      f.truth = t;
    }
    f.info.sequence = static_cast<std::uint64_t>(i);
    f.info.timestamp_ns = i * 33'000'000LL;
    f.info.camera_model = "seed";
    writer.Append(f);
  }
  writer.Close();
}

// A 4 x 3, two-frame file with the layout of libo3d3xx's HDF5 output.
void WriteIfmSeed(const fs::path& file) {
  const hid_t f = H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
  H5Pset_create_intermediate_group(lcpl, 1);
  auto write = [&](const std::string& name, hid_t type, const void* data, int rank,
                   std::uint64_t seq) {
    const hsize_t dims[3] = {3, 4, 3};
    const hid_t space = H5Screate_simple(rank, dims, nullptr);
    const hid_t d = H5Dcreate2(f, name.c_str(), type, space, lcpl, H5P_DEFAULT, H5P_DEFAULT);
    H5Dwrite(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data);
    const hid_t s = H5Screate(H5S_SCALAR);
    const std::uint64_t secs = 1447427800, nsecs = 100 * seq;
    for (auto [attr, value] :
         {std::pair{"seq", seq}, {"stamp.secs", secs}, {"stamp.nsecs", nsecs}}) {
      const hid_t a = H5Acreate2(d, attr, H5T_STD_U64LE, s, H5P_DEFAULT, H5P_DEFAULT);
      H5Awrite(a, H5T_NATIVE_UINT64, &value);
      H5Aclose(a);
    }
    H5Sclose(s);
    H5Dclose(d);
    H5Sclose(space);
  };
  std::vector<std::uint16_t> depth(12, 1500), amp(12, 800);
  std::vector<std::uint8_t> conf(12, 0);
  std::vector<std::int16_t> xyz(36, 100);
  conf[3] = 1;
  depth[3] = 0;
  for (int i = 0; i < 2; ++i) {
    const std::string id = "00000000" + std::to_string(i);
    const std::uint64_t seq = 10 - i;
    write("o3d3xx/camera/depth/" + id, H5T_NATIVE_UINT16, depth.data(), 2, seq);
    write("o3d3xx/camera/raw_amplitude/" + id, H5T_NATIVE_UINT16, amp.data(), 2, seq);
    write("o3d3xx/camera/confidence/" + id, H5T_NATIVE_UINT8, conf.data(), 2, seq);
    write("o3d3xx/camera/xyz/" + id, H5T_NATIVE_INT16, xyz.data(), 3, seq);
  }
  H5Pclose(lcpl);
  H5Fclose(f);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: fuzz_seed_writer <corpus dir> <source dir>\n");
    return 2;
  }
  try {
    const fs::path out = argv[1];
    const fs::path src = argv[2];
    for (const char* name : {"fuzz_recording", "fuzz_ifm_o3d3xx", "fuzz_adi",
                             "fuzz_azure_calibration", "fuzz_mesa_dat"}) {
      fs::create_directories(out / name);
    }
    WriteRecordingSeed(out / "fuzz_recording" / "plain.h5", 0, false);
    WriteRecordingSeed(out / "fuzz_recording" / "extras.h5", 1, true);
    WriteIfmSeed(out / "fuzz_ifm_o3d3xx" / "small.h5");
    std::string adi = {3, 2};  // 4 x 3 pixels
    for (int i = 0; i < 4 * 3 * 5; ++i) adi.push_back(static_cast<char>(i * 7));
    WriteFileAtomically(out / "fuzz_adi" / "small.bin", adi);
    WriteFileAtomically(out / "fuzz_azure_calibration" / "calibration.json",
                        ReadFile(src / "tests/data/real/azure_kinect/calibration.json"));
    WriteFileAtomically(out / "fuzz_mesa_dat" / "tiny.dat",
                        "% distance\n0.6 1.2\n2.0 nan\n% x\n0 0\n0 0\n% y\n0.8 1.6\n0 0\n"
                        "% amplitude\n100 200\n300 400\n% confidence\n1 1\n1 0\n% time: 15\n");
    // The real sample-viewer layout (issue 14): tabs, named sections, a nan-padded stamp row.
    WriteFileAtomically(out / "fuzz_mesa_dat" / "real_layout.dat",
                        "% Calibrated Distance\n0.6\t1.2\n2.0\tnan\n% Calibrated xVector\n0\t0\n"
                        "0\t0\n% Calibrated yVector\n0.8\t1.6\n0\t0\n% Amplitude\n100\t200\n"
                        "300\t400\n% Confidence map\n1\t1\n1\t0\n"
                        "% additional data / time stamp [ms]\n12345\tnan\n");
  } catch (const Error& e) {
    std::fprintf(stderr, "fuzz_seed_writer: %s\n", e.what());
    return 1;
  }
  return 0;
}

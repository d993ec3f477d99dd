// ifm O3D3xx HDF5 files as written by libo3d3xx's o3d3xx-h5 tool.
#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <vector>

#include "hdf5_util.h"
#include "import_util.h"
#include "tofcam/core/error.h"
#include "tofcam/io/importers.h"

namespace tofcam {

using io_internal::Fail;
using io_internal::Handle;

namespace {

constexpr std::size_t kMaxIfmFrames = 100000;
// All frames are held in memory: refuse more than 2^26 pixels in total (about 0.5 GB of frames;
// the sample has 3 x 23232), whatever the file claims.
constexpr std::size_t kMaxTotalPixels = std::size_t{1} << 26;
constexpr const char* kCameraGroup = "o3d3xx/camera";

herr_t CollectName(hid_t, const char* name, const H5L_info_t*, void* data) {
  auto* names = static_cast<std::vector<std::string>*>(data);
  if (names->size() >= kMaxIfmFrames) return 1;  // stop: hostile number of links
  names->emplace_back(name);
  return 0;
}

// Reads dataset `name` as a [height, width(, channels)] image of `mem_type`, checking its class,
// size and shape first.
template <typename T>
std::vector<T> ReadImage(const std::filesystem::path& file, hid_t f, const std::string& name,
                         H5T_class_t cls, std::size_t bytes, bool is_signed, hid_t mem_type,
                         const std::vector<hsize_t>& shape) {
  Handle d = io_internal::OpenDataset(file, f, name);
  io_internal::CheckType(file, d.get(), name, cls, bytes, is_signed);
  const auto dims = io_internal::DatasetDims(file, d.get(), name);
  if (dims != shape) {
    std::string want;
    for (hsize_t s : shape) want += (want.empty() ? "" : " x ") + std::to_string(s);
    Fail(ErrorCode::kFormat, file, "dataset '" + name + "' is not " + want);
  }
  std::vector<T> out;
  std::vector<hsize_t> start(shape.size(), 0);
  io_internal::ReadSlab(file, d.get(), name, mem_type, start, shape, out);
  return out;
}

std::int64_t ReadIntAttribute(const std::filesystem::path& file, hid_t f, const std::string& obj,
                              const std::string& attr, std::int64_t fallback) {
  Handle o(H5Oopen(f, obj.c_str(), H5P_DEFAULT), H5Oclose);
  if (!o.valid()) return fallback;
  std::int64_t value = fallback;
  io_internal::ReadScalarAttribute(file, o.get(), attr, H5T_NATIVE_INT64, &value);
  return value;
}

// O3D303: 176 x 132 px with a 60 deg x 45 deg field of view (data sheet); used only when the
// file has no usable xyz to fit the intrinsics to.
CameraIntrinsics IfmNominalIntrinsics(int width, int height) {
  CameraIntrinsics k;
  k.width = width;
  k.height = height;
  k.fx_px = 0.5 * width / std::tan(30.0 * kPi / 180.0);
  k.fy_px = 0.5 * height / std::tan(22.5 * kPi / 180.0);
  k.cx_px = 0.5 * (width - 1);
  k.cy_px = 0.5 * (height - 1);
  return k;
}

}  // namespace

ImportedSequence ImportIfmO3d3xx(const std::filesystem::path& h5_file) {
  io_internal::Hdf5Silencer silence;
  Handle file = io_internal::OpenFileReadOnly(h5_file);
  const hid_t f = file.get();
  const std::string depth_group = std::string(kCameraGroup) + "/depth";
  if (!io_internal::Exists(f, depth_group)) {
    Fail(ErrorCode::kFormat, h5_file, "missing group '" + depth_group + "' (not an o3d3xx file?)");
  }
  Handle group(H5Gopen2(f, depth_group.c_str(), H5P_DEFAULT), H5Gclose);
  if (!group.valid()) Fail(ErrorCode::kFormat, h5_file, "'" + depth_group + "' is not a group");
  std::vector<std::string> names;
  if (H5Literate(group.get(), H5_INDEX_NAME, H5_ITER_INC, nullptr, CollectName, &names) < 0) {
    Fail(ErrorCode::kFormat, h5_file, "cannot list '" + depth_group + "'");
  }
  if (names.empty()) Fail(ErrorCode::kFormat, h5_file, "no frames in '" + depth_group + "'");
  if (names.size() >= kMaxIfmFrames) Fail(ErrorCode::kFormat, h5_file, "too many frames");

  // Size from the first depth image.
  Handle first = io_internal::OpenDataset(h5_file, f, depth_group + "/" + names.front());
  const auto dims = io_internal::DatasetDims(h5_file, first.get(), depth_group);
  if (dims.size() != 2 || dims[0] == 0 || dims[1] == 0 || dims[0] > 2048 || dims[1] > 2048) {
    Fail(ErrorCode::kFormat, h5_file, "depth images must be 2D and at most 2048 x 2048");
  }
  const int height = static_cast<int>(dims[0]);
  const int width = static_cast<int>(dims[1]);
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (n * names.size() > kMaxTotalPixels) {
    Fail(ErrorCode::kFormat, h5_file,
         std::to_string(names.size()) + " frames of " + std::to_string(n) +
             " pixels exceed the import limit of 2^26 pixels");
  }
  const std::vector<hsize_t> shape = {dims[0], dims[1]};
  const std::vector<hsize_t> shape3 = {dims[0], dims[1], 3};

  // Capture order: the `seq` attribute (libo3d3xx names datasets in write order, which need not
  // be capture order).
  std::vector<std::int64_t> seq_numbers(names.size());
  for (std::size_t i = 0; i < names.size(); ++i) {
    seq_numbers[i] =
        ReadIntAttribute(h5_file, f, depth_group + "/" + names[i], "seq", static_cast<long>(i));
  }
  std::vector<std::size_t> order(names.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return seq_numbers[a] < seq_numbers[b]; });

  ImportedSequence seq;
  const double freq = io_internal::FrequencyForRange(kImportRangeIfmM);
  std::int64_t t0_ns = 0;
  std::vector<io_internal::PixelPoint> points;
  for (std::size_t k = 0; k < order.size(); ++k) {
    const std::string& id = names[order[k]];
    const std::string cam = std::string(kCameraGroup) + "/";
    const auto depth = ReadImage<std::uint16_t>(h5_file, f, cam + "depth/" + id, H5T_INTEGER, 2,
                                                false, H5T_NATIVE_UINT16, shape);
    const std::string amp_name = io_internal::Exists(f, cam + "raw_amplitude/" + id)
                                     ? cam + "raw_amplitude/" + id
                                     : cam + "amplitude/" + id;
    const auto amplitude = ReadImage<std::uint16_t>(h5_file, f, amp_name, H5T_INTEGER, 2, false,
                                                    H5T_NATIVE_UINT16, shape);
    const auto confidence = ReadImage<std::uint8_t>(h5_file, f, cam + "confidence/" + id,
                                                    H5T_INTEGER, 1, false, H5T_NATIVE_UINT8, shape);
    Frame frame = io_internal::BlankFrame(width, height, "ifm O3D303", freq);
    frame.info.sequence = k;
    const std::string depth_obj = cam + "depth/" + id;
    const std::int64_t secs = ReadIntAttribute(h5_file, f, depth_obj, "stamp.secs", 0);
    const std::int64_t nsecs = ReadIntAttribute(h5_file, f, depth_obj, "stamp.nsecs", 0);
    if (secs < 0 || secs > (std::int64_t{1} << 32) || nsecs < 0 || nsecs >= 1'000'000'000) {
      Fail(ErrorCode::kFormat, h5_file, "stamp of '" + depth_obj + "' out of range");
    }
    const std::int64_t t_ns = secs * 1'000'000'000 + nsecs;
    if (k == 0) t0_ns = t_ns;
    frame.info.timestamp_ns = t_ns - t0_ns;
    for (std::size_t i = 0; i < n; ++i) {
      io_internal::SetDistanceMm(frame, i, depth[i], kImportRangeIfmM);
      io_internal::SetAmplitude(frame, i, amplitude[i]);
      const std::uint8_t c = confidence[i];
      if (c & 0x01) frame.source_flags[i].Set(Flag::kInvalid);
      if (c & 0x02) frame.source_flags[i].Set(Flag::kSaturated);
      if (c & 0x04) frame.source_flags[i].Set(Flag::kInvalid);  // bad symmetry (motion)
      if (c & 0x08) frame.source_flags[i].Set(Flag::kLowAmplitude);
    }
    // The camera's own Cartesian points (ifm frame: x forward, y left, z up, mm) fix the
    // intrinsics; taken from the first frame that has them.
    if (points.empty() && io_internal::Exists(f, cam + "xyz/" + id)) {
      const auto xyz = ReadImage<std::int16_t>(h5_file, f, cam + "xyz/" + id, H5T_INTEGER, 2, true,
                                               H5T_NATIVE_INT16, shape3);
      for (std::size_t i = 0; i < n; ++i) {
        if (!frame.source_flags[i].Valid() || xyz[3 * i] <= 0) continue;
        points.push_back({static_cast<double>(i % width), static_cast<double>(i / width),
                          -static_cast<double>(xyz[3 * i + 1]),
                          -static_cast<double>(xyz[3 * i + 2]), static_cast<double>(xyz[3 * i])});
      }
    }
    seq.frames.push_back(std::move(frame));
  }
  seq.camera = io_internal::ImportedCameraInfo(
      "ifm O3D303",
      io_internal::FitPinhole(points, width, height, IfmNominalIntrinsics(width, height)), freq);
  if (const std::optional<double> scale = SelfCalibratedNoiseScale(seq.frames)) {
    seq.delta_l_scale = scale;
    seq.delta_l_scale_note = "fitted at import from the temporal noise of the file's " +
                             std::to_string(seq.frames.size()) + " frames";
  }
  return seq;
}

}  // namespace tofcam

#include "tofcam/io/recording.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "hdf5_util.h"
#include "tofcam/core/error.h"
#include "tofcam/version.h"

namespace tofcam {

using io_internal::Fail;
using io_internal::Handle;
using io_internal::Hdf5Silencer;

namespace {

constexpr const char* kFormatName = "tofcam-recording";
// Hostile-size guards: ToF sensors have at most about 1 Mpixel, so a frame over 2^22 pixels
// (2048 x 2048) or 2^14 pixels per side is refused (reading one would allocate tens of MB per
// channel); a recording of more than 2^24 frames (a week at 30 Hz) is not plausible, and reading
// the per-frame info of a claimed larger count would allocate gigabytes.
constexpr hsize_t kMaxSide = 1 << 14;
constexpr long long kMaxFramePixels = 1LL << 22;
constexpr hsize_t kMaxFrames = 1 << 24;

// Image channels: dataset name, HDF5 file type, native memory type.
struct ChannelSpec {
  const char* name;
  hid_t file_type;
  hid_t mem_type;
};

// Per-frame info datasets, in the order of InfoColumns below.
constexpr const char* kInfoNames[] = {"info/sequence",
                                      "info/timestamp_ns",
                                      "info/integration_time_register",
                                      "info/integration_time_us",
                                      "info/modulation_frequency_hz",
                                      "info/pan_angle_rad",
                                      "info/distance_offset_register",
                                      "info/has_intensity"};
constexpr int kInfoCount = 8;

hid_t InfoFileType(int i) {
  switch (i) {
    case 0:
      return H5T_STD_U64LE;
    case 1:
      return H5T_STD_I64LE;
    case 2:
    case 6:
      return H5T_STD_I32LE;
    case 7:
      return H5T_STD_U8LE;
    default:
      return H5T_IEEE_F64LE;
  }
}

hid_t InfoMemType(int i) {
  switch (i) {
    case 0:
      return H5T_NATIVE_UINT64;
    case 1:
      return H5T_NATIVE_INT64;
    case 2:
    case 6:
      return H5T_NATIVE_INT32;
    case 7:
      return H5T_NATIVE_UINT8;
    default:
      return H5T_NATIVE_DOUBLE;
  }
}

std::vector<double> IntrinsicsVector(const CameraIntrinsics& k) {
  return {k.fx_px, k.fy_px, k.cx_px, k.cy_px, k.k1, k.k2, k.k3, k.k4, k.k5, k.k6, k.p1, k.p2};
}

}  // namespace

void RecordingOptions::Validate() const {
  if (compression_level < 0 || compression_level > 9) {
    throw Error(ErrorCode::kInvalidArgument, "RecordingOptions::compression_level " +
                                                 std::to_string(compression_level) +
                                                 " outside 0..9");
  }
}

void PlaybackOptions::Validate() const {
  if (!(speed > 0) || !std::isfinite(speed)) {
    throw Error(ErrorCode::kInvalidArgument,
                "PlaybackOptions::speed must be > 0 and finite, got " + std::to_string(speed));
  }
}

// ---------------------------------------------------------------------------------------------
// Writer

struct RecordingWriter::Impl {
  std::filesystem::path path;
  CameraInfo camera;
  RecordingOptions options;
  Handle file;
  std::vector<std::pair<std::string, Handle>> images;  // name -> dataset
  std::vector<Handle> info;
  bool has_flags = false;
  bool has_truth = false;
  bool has_footprint = false;  // truth/footprint_near_m and _far_m
  bool has_confidence = false;
  std::string frame_model;
  std::size_t count = 0;
  std::int64_t last_timestamp_ns = 0;  // frame count - 1's (when count > 0)
  bool closed = false;

  Handle CreateImageDataset(const std::string& name, hid_t file_type) {
    const hsize_t dims[3] = {0, static_cast<hsize_t>(camera.height()),
                             static_cast<hsize_t>(camera.width())};
    const hsize_t max_dims[3] = {H5S_UNLIMITED, dims[1], dims[2]};
    const hsize_t chunk[3] = {1, dims[1], dims[2]};
    Handle space(H5Screate_simple(3, dims, max_dims), H5Sclose);
    Handle dcpl(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
    H5Pset_chunk(dcpl.get(), 3, chunk);
    if (options.compression_level > 0) {
      H5Pset_shuffle(dcpl.get());
      H5Pset_deflate(dcpl.get(), static_cast<unsigned>(options.compression_level));
    }
    Handle lcpl(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
    H5Pset_create_intermediate_group(lcpl.get(), 1);
    Handle d(H5Dcreate2(file.get(), name.c_str(), file_type, space.get(), lcpl.get(), dcpl.get(),
                        H5P_DEFAULT),
             H5Dclose);
    if (!d.valid()) Fail(ErrorCode::kIo, path, "cannot create dataset '" + name + "'");
    return d;
  }

  void CreateDatasets(const Frame& first) {
    has_flags = !first.source_flags.empty();
    has_truth = first.truth.has_value();
    has_footprint = has_truth && !first.truth->footprint_near_m.empty();
    has_confidence = !first.confidence.empty();
    frame_model = first.info.camera_model;
    images.emplace_back("distance", CreateImageDataset("distance", H5T_STD_U16LE));
    images.emplace_back("amplitude", CreateImageDataset("amplitude", H5T_STD_U16LE));
    images.emplace_back("intensity", CreateImageDataset("intensity", H5T_STD_U16LE));
    if (has_flags) {
      images.emplace_back("source_flags", CreateImageDataset("source_flags", H5T_STD_U16LE));
    }
    if (has_confidence) {
      images.emplace_back("confidence", CreateImageDataset("confidence", H5T_IEEE_F32LE));
    }
    if (has_truth) {
      images.emplace_back("truth/radial_distance_m",
                          CreateImageDataset("truth/radial_distance_m", H5T_IEEE_F32LE));
      images.emplace_back("truth/causes", CreateImageDataset("truth/causes", H5T_STD_U16LE));
      images.emplace_back("truth/sigma_m", CreateImageDataset("truth/sigma_m", H5T_IEEE_F32LE));
      if (has_footprint) {
        for (const char* name : {"truth/footprint_near_m", "truth/footprint_far_m"}) {
          images.emplace_back(name, CreateImageDataset(name, H5T_IEEE_F32LE));
        }
      }
    }
    for (int i = 0; i < kInfoCount; ++i) {
      const hsize_t dims[1] = {0};
      const hsize_t max_dims[1] = {H5S_UNLIMITED};
      const hsize_t chunk[1] = {256};
      Handle space(H5Screate_simple(1, dims, max_dims), H5Sclose);
      Handle dcpl(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
      H5Pset_chunk(dcpl.get(), 1, chunk);
      Handle lcpl(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
      H5Pset_create_intermediate_group(lcpl.get(), 1);
      Handle d(H5Dcreate2(file.get(), kInfoNames[i], InfoFileType(i), space.get(), lcpl.get(),
                          dcpl.get(), H5P_DEFAULT),
               H5Dclose);
      if (!d.valid()) Fail(ErrorCode::kIo, path, std::string("cannot create ") + kInfoNames[i]);
      info.push_back(std::move(d));
    }
    const std::uint8_t flags = has_flags ? 1 : 0;
    const std::uint8_t truth = has_truth ? 1 : 0;
    io_internal::WriteScalarAttribute(path, file.get(), "has_source_flags", H5T_NATIVE_UINT8,
                                      &flags);
    io_internal::WriteScalarAttribute(path, file.get(), "has_frame_truth", H5T_NATIVE_UINT8,
                                      &truth);
    // Absent in files written before the footprint existed: read as "none".
    const std::uint8_t footprint = has_footprint ? 1 : 0;
    io_internal::WriteScalarAttribute(path, file.get(), "has_truth_footprint", H5T_NATIVE_UINT8,
                                      &footprint);
    io_internal::WriteStringAttribute(path, file.get(), "frame_camera_model", frame_model);
    // Absent in files written before the confidence channel existed: read as "none".
    const std::uint8_t confidence = has_confidence ? 1 : 0;
    io_internal::WriteScalarAttribute(path, file.get(), "has_confidence", H5T_NATIVE_UINT8,
                                      &confidence);
    io_internal::WriteStringAttribute(path, file.get(), "confidence_source",
                                      first.info.confidence_source);
  }

  // Grows a dataset by one frame along dimension 0 and writes `data` into the new slot.
  void AppendRow(hid_t dataset, const std::string& name, hid_t mem_type, const void* data) {
    Handle space(H5Dget_space(dataset), H5Sclose);
    const int rank = H5Sget_simple_extent_ndims(space.get());
    hsize_t dims[3] = {0, 0, 0};
    H5Sget_simple_extent_dims(space.get(), dims, nullptr);
    dims[0] = count + 1;
    if (H5Dset_extent(dataset, dims) < 0) {
      Fail(ErrorCode::kIo, path, "cannot extend dataset '" + name + "'");
    }
    Handle file_space(H5Dget_space(dataset), H5Sclose);
    hsize_t start[3] = {count, 0, 0};
    hsize_t block[3] = {1, dims[1], dims[2]};
    H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, block, nullptr);
    Handle mem_space(H5Screate_simple(rank, block, nullptr), H5Sclose);
    if (H5Dwrite(dataset, mem_type, mem_space.get(), file_space.get(), H5P_DEFAULT, data) < 0) {
      Fail(ErrorCode::kIo, path,
           "cannot write frame " + std::to_string(count) + " of '" + name + "' (disk full?)");
    }
  }
};

RecordingWriter::RecordingWriter(const std::filesystem::path& path, const CameraInfo& camera,
                                 const RecordingOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Validate();
  camera.intrinsics.Validate();
  // What the reader would refuse is not written: the same size limits (hostile-size guards).
  const int cam_w = camera.width(), cam_h = camera.height();
  if (static_cast<hsize_t>(cam_w) > kMaxSide || static_cast<hsize_t>(cam_h) > kMaxSide ||
      static_cast<long long>(cam_w) * cam_h > kMaxFramePixels) {
    throw Error(ErrorCode::kInvalidArgument,
                path.string() + ": a recording holds frames of at most " +
                    std::to_string(kMaxFramePixels) + " pixels and " + std::to_string(kMaxSide) +
                    " per side; the camera's are " + std::to_string(cam_w) + " x " +
                    std::to_string(cam_h));
  }
  if (camera.model.size() + 1 > io_internal::kMaxStringAttributeBytes ||
      options.calibration_id.size() + 1 > io_internal::kMaxStringAttributeBytes) {
    // Checked before the file is created (H5F_ACC_TRUNC would empty an existing one).
    throw Error(ErrorCode::kInvalidArgument, path.string() + ": the camera model's name (" +
                                                 std::to_string(camera.model.size()) +
                                                 " bytes) or the calibration id (" +
                                                 std::to_string(options.calibration_id.size()) +
                                                 " bytes) is longer than a recording holds");
  }
  if (!(camera.modulation_frequency_hz > 0) || !std::isfinite(camera.modulation_frequency_hz)) {
    throw Error(ErrorCode::kInvalidArgument,
                path.string() + ": camera modulation frequency must be > 0 and finite");
  }
  Hdf5Silencer silence;
  if (options.compression_level > 0 &&
      (H5Zfilter_avail(H5Z_FILTER_DEFLATE) <= 0 || H5Zfilter_avail(H5Z_FILTER_SHUFFLE) <= 0)) {
    throw Error(ErrorCode::kUnsupported, "this HDF5 build has no deflate filter");
  }
  impl_->path = path;
  impl_->camera = camera;
  impl_->options = options;
  // The HDF5 1.8 file format: superblock v2 and object headers with checksums, so the reader
  // detects damaged metadata instead of parsing it, and still readable by HDF5 1.8 and MATLAB.
  Handle fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
  if (!fapl.valid() || H5Pset_libver_bounds(fapl.get(), H5F_LIBVER_V18, H5F_LIBVER_V18) < 0) {
    Fail(ErrorCode::kInternal, path, "cannot set the HDF5 file format");
  }
  impl_->file = Handle(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get()), H5Fclose);
  if (!impl_->file.valid()) Fail(ErrorCode::kIo, path, "cannot create recording");
  const hid_t f = impl_->file.get();
  using io_internal::WriteScalarAttribute;
  using io_internal::WriteStringAttribute;
  WriteStringAttribute(path, f, "format", kFormatName);
  const std::int32_t version = kRecordingFormatVersion;
  WriteScalarAttribute(path, f, "format_version", H5T_NATIVE_INT32, &version);
  WriteStringAttribute(path, f, "tofcam_version", kVersionString);
  WriteStringAttribute(path, f, "camera_model", camera.model);
  WriteStringAttribute(path, f, "calibration_id", options.calibration_id);
  const std::int32_t w = camera.width(), h = camera.height();
  WriteScalarAttribute(path, f, "width", H5T_NATIVE_INT32, &w);
  WriteScalarAttribute(path, f, "height", H5T_NATIVE_INT32, &h);
  io_internal::WriteDoubleArrayAttribute(path, f, "intrinsics",
                                         IntrinsicsVector(camera.intrinsics));
  WriteScalarAttribute(path, f, "modulation_frequency_hz", H5T_NATIVE_DOUBLE,
                       &camera.modulation_frequency_hz);
  WriteScalarAttribute(path, f, "integration_time_step_us", H5T_NATIVE_DOUBLE,
                       &camera.integration_time_step_us);
  WriteScalarAttribute(path, f, "integration_time_base_us", H5T_NATIVE_DOUBLE,
                       &camera.integration_time_base_us);
  const std::int32_t min_reg = camera.min_integration_register;
  const std::int32_t max_reg = camera.max_integration_register;
  WriteScalarAttribute(path, f, "min_integration_register", H5T_NATIVE_INT32, &min_reg);
  WriteScalarAttribute(path, f, "max_integration_register", H5T_NATIVE_INT32, &max_reg);
  WriteScalarAttribute(path, f, "max_frame_rate_hz", H5T_NATIVE_DOUBLE, &camera.max_frame_rate_hz);
  const std::uint8_t has_intensity = camera.has_intensity ? 1 : 0;
  const std::uint8_t has_truth = camera.has_ground_truth ? 1 : 0;
  WriteScalarAttribute(path, f, "has_intensity", H5T_NATIVE_UINT8, &has_intensity);
  WriteScalarAttribute(path, f, "has_ground_truth", H5T_NATIVE_UINT8, &has_truth);
  const std::uint64_t zero = 0;
  WriteScalarAttribute(path, f, "frame_count", H5T_NATIVE_UINT64, &zero);
  if (H5Fflush(f, H5F_SCOPE_GLOBAL) < 0) Fail(ErrorCode::kIo, path, "cannot flush recording");
}

RecordingWriter::~RecordingWriter() {
  try {
    Close();
  } catch (...) {  // NOLINT(bugprone-empty-catch): a destructor must not throw; Close() reports.
  }
}

void RecordingWriter::Append(const Frame& frame) {
  Impl& m = *impl_;
  if (m.closed) {
    throw Error(ErrorCode::kInvalidArgument, m.path.string() + ": Append() after Close()");
  }
  ValidateFrame(frame, m.path.string() + " frame " + std::to_string(m.count));
  // The reader refuses a recording whose timestamps decrease: refuse to write one.
  if (m.count > 0 && frame.info.timestamp_ns < m.last_timestamp_ns) {
    throw Error(ErrorCode::kInvalidArgument,
                m.path.string() + ": frame " + std::to_string(m.count) + "'s timestamp " +
                    std::to_string(frame.info.timestamp_ns) +
                    " ns is before the previous frame's " + std::to_string(m.last_timestamp_ns) +
                    " ns (timestamps may not decrease)");
  }
  if (!frame.distance.SameSize(m.camera.width(), m.camera.height())) {
    throw Error(ErrorCode::kMismatch,
                m.path.string() + ": frame is " + std::to_string(frame.width()) + "x" +
                    std::to_string(frame.height()) + ", recording is " +
                    std::to_string(m.camera.width()) + "x" + std::to_string(m.camera.height()));
  }
  if (!frame.source_flags.empty() && !frame.source_flags.SameSize(frame.distance)) {
    throw Error(ErrorCode::kMismatch, m.path.string() + ": source_flags size differs from frame");
  }
  // ValidateFrame checked every channel's size; a recording also needs the truth's σ.
  if (frame.truth && frame.truth->sigma_m.empty()) {
    throw Error(ErrorCode::kMismatch, m.path.string() + ": ground truth without sigma_m");
  }
  // The first frame's strings become attributes: too long for the reader, refused before any
  // dataset exists (a half-made file would fail every later Append).
  if (m.count == 0 &&
      (frame.info.camera_model.size() + 1 > io_internal::kMaxStringAttributeBytes ||
       frame.info.confidence_source.size() + 1 > io_internal::kMaxStringAttributeBytes)) {
    throw Error(ErrorCode::kInvalidArgument,
                m.path.string() +
                    ": the frame's camera_model or confidence_source is longer than " +
                    std::to_string(io_internal::kMaxStringAttributeBytes - 1) +
                    " bytes, more than a recording holds");
  }
  Hdf5Silencer silence;
  if (m.count == 0) m.CreateDatasets(frame);
  if (m.has_flags == frame.source_flags.empty() || m.has_truth != frame.truth.has_value() ||
      m.has_confidence == frame.confidence.empty() ||
      (m.has_truth && m.has_footprint == frame.truth->footprint_near_m.empty())) {
    throw Error(ErrorCode::kMismatch,
                m.path.string() +
                    ": every frame of a recording must have source flags, confidence, ground "
                    "truth and its footprint iff the first frame had them");
  }
  if (frame.info.camera_model != m.frame_model) {
    throw Error(ErrorCode::kMismatch, m.path.string() + ": frame camera model '" +
                                          frame.info.camera_model + "' differs from '" +
                                          m.frame_model + "'");
  }
  std::size_t slot = 0;
  auto next = [&]() -> std::pair<std::string, Handle>& { return m.images[slot++]; };
  auto write_u16 = [&](const void* data) {
    auto& [name, d] = next();
    m.AppendRow(d.get(), name, H5T_NATIVE_UINT16, data);
  };
  write_u16(frame.distance.data());
  write_u16(frame.amplitude.data());
  write_u16(frame.intensity.data());
  if (m.has_flags) write_u16(frame.source_flags.data());  // PixelFlags is a uint16_t (asserted)
  if (m.has_confidence) {
    auto& [name, d] = next();
    m.AppendRow(d.get(), name, H5T_NATIVE_FLOAT, frame.confidence.data());
  }
  if (m.has_truth) {
    const GroundTruth& t = *frame.truth;
    auto& [n0, d0] = next();
    m.AppendRow(d0.get(), n0, H5T_NATIVE_FLOAT, t.radial_distance_m.data());
    write_u16(t.causes.data());
    auto& [n2, d2] = next();
    m.AppendRow(d2.get(), n2, H5T_NATIVE_FLOAT, t.sigma_m.data());
    if (m.has_footprint) {
      for (const Image<float>* image : {&t.footprint_near_m, &t.footprint_far_m}) {
        auto& [name, d] = next();
        m.AppendRow(d.get(), name, H5T_NATIVE_FLOAT, image->data());
      }
    }
  }
  const FrameInfo& fi = frame.info;
  const std::uint64_t sequence = fi.sequence;
  const std::int64_t timestamp = fi.timestamp_ns;
  const std::int32_t it_reg = fi.integration_time_register;
  const std::int32_t offset_reg = fi.distance_offset_register;
  const std::uint8_t has_intensity = fi.has_intensity ? 1 : 0;
  const void* values[kInfoCount] = {&sequence,
                                    &timestamp,
                                    &it_reg,
                                    &fi.integration_time_us,
                                    &fi.modulation_frequency_hz,
                                    &fi.pan_angle_rad,
                                    &offset_reg,
                                    &has_intensity};
  for (int i = 0; i < kInfoCount; ++i) {
    m.AppendRow(m.info[i].get(), kInfoNames[i], InfoMemType(i), values[i]);
  }
  // The committed count is written last: a reader trusts only frames below it. Two flushes put
  // it on disk strictly after the frame. One flush writes the raw data first, but then its dirty
  // metadata in the metadata cache's own order (by file address), which need not put the count
  // after the datasets' chunk indexes; a recorder killed inside that flush could then leave the
  // new count beside a frame that was not wholly on disk. The kill test read such a frame back
  // wrong twice in about 130 rounds on a loaded machine. The frame first, then the count.
  const auto flush = [&m] {
    if (m.options.flush_each_frame && H5Fflush(m.file.get(), H5F_SCOPE_GLOBAL) < 0) {
      Fail(ErrorCode::kIo, m.path, "cannot flush recording (disk full?)");
    }
  };
  flush();
  const std::uint64_t committed = m.count + 1;
  io_internal::WriteScalarAttribute(m.path, m.file.get(), "frame_count", H5T_NATIVE_UINT64,
                                    &committed);
  flush();
  ++m.count;
  m.last_timestamp_ns = frame.info.timestamp_ns;
}

void RecordingWriter::Close() {
  Impl& m = *impl_;
  if (m.closed) return;
  m.closed = true;
  Hdf5Silencer silence;
  m.images.clear();
  m.info.clear();
  const bool flushed = H5Fflush(m.file.get(), H5F_SCOPE_GLOBAL) >= 0;
  const bool closed = m.file.Reset();
  if (!flushed || !closed) Fail(ErrorCode::kIo, m.path, "cannot close recording");
}

std::size_t RecordingWriter::frame_count() const noexcept { return impl_->count; }
const std::filesystem::path& RecordingWriter::path() const noexcept { return impl_->path; }

// ---------------------------------------------------------------------------------------------
// Reader

struct RecordingReader::Impl {
  std::filesystem::path path;
  Handle file;
  RecordingMetadata meta;
  std::size_t count = 0;
  std::vector<FrameInfo> infos;
  Handle distance, amplitude, intensity, flags, confidence, truth_distance, truth_causes,
      truth_sigma, truth_near, truth_far;
  bool has_footprint = false;
  std::string confidence_source;

  template <typename T>
  T RequireScalar(const std::string& name, hid_t mem_type) {
    T value{};
    if (!io_internal::ReadScalarAttribute(path, file.get(), name, mem_type, &value)) {
      Fail(ErrorCode::kFormat, path, "missing attribute '" + name + "'");
    }
    return value;
  }
  double RequireFinite(const std::string& name) {
    const auto v = RequireScalar<double>(name, H5T_NATIVE_DOUBLE);
    if (!std::isfinite(v)) Fail(ErrorCode::kFormat, path, "attribute '" + name + "' not finite");
    return v;
  }
  std::string RequireString(const std::string& name) {
    std::string s;
    if (!io_internal::ReadStringAttribute(path, file.get(), name, s)) {
      Fail(ErrorCode::kFormat, path, "missing attribute '" + name + "'");
    }
    return s;
  }

  // Opens an image dataset and checks type and shape [n, height, width]; returns n.
  hsize_t OpenImage(Handle& out, const std::string& name, H5T_class_t cls, std::size_t bytes) {
    out = io_internal::OpenDataset(path, file.get(), name);
    io_internal::CheckType(path, out.get(), name, cls, bytes);
    const auto dims = io_internal::DatasetDims(path, out.get(), name);
    const auto w = static_cast<hsize_t>(meta.camera.width());
    const auto h = static_cast<hsize_t>(meta.camera.height());
    if (dims.size() != 3 || dims[1] != h || dims[2] != w) {
      Fail(ErrorCode::kFormat, path,
           "dataset '" + name + "' is not frames x " + std::to_string(h) + " x " +
               std::to_string(w));
    }
    return dims[0];
  }

  void Open() {
    if (RequireString("format") != kFormatName) {
      Fail(ErrorCode::kFormat, path, "not a tofcam recording (attribute 'format')");
    }
    meta.format_version = RequireScalar<std::int32_t>("format_version", H5T_NATIVE_INT32);
    if (meta.format_version != kRecordingFormatVersion) {
      Fail(ErrorCode::kUnsupported, path,
           "recording format version " + std::to_string(meta.format_version) +
               " (this tofcam reads " + std::to_string(kRecordingFormatVersion) + ")");
    }
    io_internal::ReadStringAttribute(path, file.get(), "tofcam_version", meta.tofcam_version);
    CameraInfo& cam = meta.camera;
    cam.model = RequireString("camera_model");
    meta.calibration_id = RequireString("calibration_id");
    meta.frame_camera_model = cam.model;
    io_internal::ReadStringAttribute(path, file.get(), "frame_camera_model",
                                     meta.frame_camera_model);
    const auto w = RequireScalar<std::int32_t>("width", H5T_NATIVE_INT32);
    const auto h = RequireScalar<std::int32_t>("height", H5T_NATIVE_INT32);
    if (w <= 0 || h <= 0 || static_cast<hsize_t>(w) > kMaxSide ||
        static_cast<hsize_t>(h) > kMaxSide || static_cast<long long>(w) * h > kMaxFramePixels) {
      Fail(ErrorCode::kFormat, path,
           "hostile image size " + std::to_string(w) + " x " + std::to_string(h));
    }
    std::vector<double> k;
    if (!io_internal::ReadDoubleArrayAttribute(path, file.get(), "intrinsics", 12, k) ||
        k.size() != 12) {
      Fail(ErrorCode::kFormat, path, "attribute 'intrinsics' missing or not 12 values");
    }
    CameraIntrinsics& in = cam.intrinsics;
    in.width = w;
    in.height = h;
    in.fx_px = k[0], in.fy_px = k[1], in.cx_px = k[2], in.cy_px = k[3];
    in.k1 = k[4], in.k2 = k[5], in.k3 = k[6], in.k4 = k[7], in.k5 = k[8], in.k6 = k[9];
    in.p1 = k[10], in.p2 = k[11];
    try {
      in.Validate();
    } catch (const Error& e) {
      Fail(ErrorCode::kFormat, path, std::string("invalid intrinsics: ") + e.what());
    }
    cam.modulation_frequency_hz = RequireFinite("modulation_frequency_hz");
    if (!(cam.modulation_frequency_hz > 0)) {
      Fail(ErrorCode::kFormat, path, "modulation_frequency_hz must be > 0");
    }
    cam.integration_time_step_us = RequireFinite("integration_time_step_us");
    cam.integration_time_base_us = RequireFinite("integration_time_base_us");
    cam.min_integration_register =
        RequireScalar<std::int32_t>("min_integration_register", H5T_NATIVE_INT32);
    cam.max_integration_register =
        RequireScalar<std::int32_t>("max_integration_register", H5T_NATIVE_INT32);
    if (cam.min_integration_register > cam.max_integration_register) {
      Fail(ErrorCode::kFormat, path, "min_integration_register > max_integration_register");
    }
    cam.max_frame_rate_hz = RequireFinite("max_frame_rate_hz");
    cam.has_intensity = RequireScalar<std::uint8_t>("has_intensity", H5T_NATIVE_UINT8) != 0;
    cam.has_ground_truth = RequireScalar<std::uint8_t>("has_ground_truth", H5T_NATIVE_UINT8) != 0;
    const auto committed = RequireScalar<std::uint64_t>("frame_count", H5T_NATIVE_UINT64);
    if (committed == 0) return;  // a recorder killed before its first frame: empty recording
    if (committed > kMaxFrames) {
      Fail(ErrorCode::kFormat, path, "hostile frame_count " + std::to_string(committed));
    }
    hsize_t n = committed;
    std::uint8_t has_flags = 0, has_truth = 0;
    io_internal::ReadScalarAttribute(path, file.get(), "has_source_flags", H5T_NATIVE_UINT8,
                                     &has_flags);
    io_internal::ReadScalarAttribute(path, file.get(), "has_frame_truth", H5T_NATIVE_UINT8,
                                     &has_truth);
    meta.has_source_flags = has_flags != 0;
    meta.has_ground_truth = has_truth != 0;
    std::uint8_t has_confidence = 0;
    io_internal::ReadScalarAttribute(path, file.get(), "has_confidence", H5T_NATIVE_UINT8,
                                     &has_confidence);
    meta.has_confidence = has_confidence != 0;
    if (meta.has_confidence) {
      io_internal::ReadStringAttribute(path, file.get(), "confidence_source", confidence_source);
      n = std::min(n, OpenImage(confidence, "confidence", H5T_FLOAT, 4));
    }
    n = std::min(n, OpenImage(distance, "distance", H5T_INTEGER, 2));
    n = std::min(n, OpenImage(amplitude, "amplitude", H5T_INTEGER, 2));
    n = std::min(n, OpenImage(intensity, "intensity", H5T_INTEGER, 2));
    if (meta.has_source_flags) n = std::min(n, OpenImage(flags, "source_flags", H5T_INTEGER, 2));
    if (meta.has_ground_truth) {
      n = std::min(n, OpenImage(truth_distance, "truth/radial_distance_m", H5T_FLOAT, 4));
      n = std::min(n, OpenImage(truth_causes, "truth/causes", H5T_INTEGER, 2));
      n = std::min(n, OpenImage(truth_sigma, "truth/sigma_m", H5T_FLOAT, 4));
      std::uint8_t footprint = 0;
      io_internal::ReadScalarAttribute(path, file.get(), "has_truth_footprint", H5T_NATIVE_UINT8,
                                       &footprint);
      has_footprint = footprint != 0;
      meta.has_truth_footprint = has_footprint;
      if (has_footprint) {
        n = std::min(n, OpenImage(truth_near, "truth/footprint_near_m", H5T_FLOAT, 4));
        n = std::min(n, OpenImage(truth_far, "truth/footprint_far_m", H5T_FLOAT, 4));
      }
    }
    // Per-frame info, read whole and validated once.
    std::vector<std::vector<double>> columns(kInfoCount);
    std::vector<std::uint64_t> sequence;
    std::vector<std::int64_t> timestamps;
    for (int i = 0; i < kInfoCount; ++i) {
      Handle d = io_internal::OpenDataset(path, file.get(), kInfoNames[i]);
      const auto dims = io_internal::DatasetDims(path, d.get(), kInfoNames[i]);
      if (dims.size() != 1) Fail(ErrorCode::kFormat, path, std::string(kInfoNames[i]) + " not 1D");
      n = std::min(n, dims[0]);
      const H5T_class_t cls = (i >= 3 && i <= 5) ? H5T_FLOAT : H5T_INTEGER;
      Handle type(H5Dget_type(d.get()), H5Tclose);
      if (!type.valid() || H5Tget_class(type.get()) != cls) {
        Fail(ErrorCode::kFormat, path, std::string(kInfoNames[i]) + " has the wrong type");
      }
      if (n == 0) continue;
      if (i == 0) {
        io_internal::ReadSlab(path, d.get(), kInfoNames[i], H5T_NATIVE_UINT64, {0}, {n}, sequence);
      } else if (i == 1) {
        io_internal::ReadSlab(path, d.get(), kInfoNames[i], H5T_NATIVE_INT64, {0}, {n}, timestamps);
      } else {
        io_internal::ReadSlab(path, d.get(), kInfoNames[i], H5T_NATIVE_DOUBLE, {0}, {n},
                              columns[i]);
      }
    }
    count = static_cast<std::size_t>(n);
    infos.resize(count);
    for (std::size_t j = 0; j < count; ++j) {
      FrameInfo& fi = infos[j];
      const std::string where = " of frame " + std::to_string(j);
      fi.sequence = sequence[j];
      fi.timestamp_ns = timestamps[j];
      if (j > 0 && timestamps[j] < timestamps[j - 1]) {
        Fail(ErrorCode::kFormat, path, "timestamps decrease at frame " + std::to_string(j));
      }
      for (int i = 2; i < kInfoCount; ++i) {
        if (!std::isfinite(columns[i][j])) {
          Fail(ErrorCode::kFormat, path, std::string(kInfoNames[i]) + " not finite" + where);
        }
      }
      auto to_int = [&](double v, const char* name) {
        if (v < std::numeric_limits<int>::min() || v > std::numeric_limits<int>::max()) {
          Fail(ErrorCode::kFormat, path, std::string(name) + " out of range" + where);
        }
        return static_cast<int>(v);
      };
      fi.integration_time_register = to_int(columns[2][j], kInfoNames[2]);
      fi.integration_time_us = columns[3][j];
      fi.modulation_frequency_hz = columns[4][j];
      if (!(fi.modulation_frequency_hz > 0)) {
        Fail(ErrorCode::kFormat, path, "modulation frequency not > 0" + where);
      }
      fi.pan_angle_rad = columns[5][j];
      fi.distance_offset_register = to_int(columns[6][j], kInfoNames[6]);
      fi.has_intensity = columns[7][j] != 0;
      fi.camera_model = meta.frame_camera_model;
    }
  }

  template <typename T>
  void ReadImage(const Handle& d, const std::string& name, hid_t mem_type, std::size_t index,
                 Image<T>& out) const {
    const auto h = static_cast<hsize_t>(meta.camera.height());
    const auto w = static_cast<hsize_t>(meta.camera.width());
    out = Image<T>(meta.camera.width(), meta.camera.height());
    static_assert(sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4 || sizeof(T) == 8);
    if (H5Tget_size(mem_type) != sizeof(T)) {
      Fail(ErrorCode::kInternal, path, "read of '" + name + "' into a wrong-sized type");
    }
    // Checked against a damaged file's chunks (hdf5_util.h); its errors name file and dataset.
    io_internal::ReadSelection(path, d.get(), name, mem_type, {index, 0, 0}, {1, h, w}, out.data());
  }
};

RecordingReader::RecordingReader(const std::filesystem::path& path)
    : impl_(std::make_unique<Impl>()) {
  Hdf5Silencer silence;
  impl_->path = path;
  impl_->file = io_internal::OpenFileReadOnly(path);
  // Recordings are written with checksummed metadata (superblock >= 2); refusing older layouts
  // keeps unchecked (possibly damaged) metadata away from libhdf5's parsers.
  H5F_info2_t info;
  if (H5Fget_info2(impl_->file.get(), &info) < 0 || info.super.version < 2) {
    Fail(ErrorCode::kFormat, path, "not a tofcam recording (HDF5 superblock without checksums)");
  }
  impl_->Open();
}

RecordingReader::~RecordingReader() {
  if (impl_ != nullptr) {
    Hdf5Silencer silence;
    impl_.reset();
  }
}
RecordingReader::RecordingReader(RecordingReader&&) noexcept = default;
RecordingReader& RecordingReader::operator=(RecordingReader&&) noexcept = default;

std::size_t RecordingReader::frame_count() const noexcept { return impl_->count; }
const RecordingMetadata& RecordingReader::metadata() const noexcept { return impl_->meta; }
const std::filesystem::path& RecordingReader::path() const noexcept { return impl_->path; }

const FrameInfo& RecordingReader::Info(std::size_t index) const {
  if (index >= impl_->count) {
    throw Error(ErrorCode::kInvalidArgument,
                impl_->path.string() + ": frame index " + std::to_string(index) +
                    " out of range (frames: " + std::to_string(impl_->count) + ")");
  }
  return impl_->infos[index];
}

Frame RecordingReader::Read(std::size_t index) const {
  const Impl& m = *impl_;
  Frame frame;
  frame.info = Info(index);
  Hdf5Silencer silence;
  m.ReadImage(m.distance, "distance", H5T_NATIVE_UINT16, index, frame.distance);
  m.ReadImage(m.amplitude, "amplitude", H5T_NATIVE_UINT16, index, frame.amplitude);
  m.ReadImage(m.intensity, "intensity", H5T_NATIVE_UINT16, index, frame.intensity);
  if (m.meta.has_source_flags) {
    m.ReadImage(m.flags, "source_flags", H5T_NATIVE_UINT16, index, frame.source_flags);
  }
  if (m.meta.has_confidence) {
    m.ReadImage(m.confidence, "confidence", H5T_NATIVE_FLOAT, index, frame.confidence);
    frame.info.confidence_source = m.confidence_source;
    for (std::size_t i = 0; i < frame.confidence.size(); ++i) {
      const float c = frame.confidence[i];
      if (!(c >= 0.0f) || std::isinf(c)) {
        Fail(ErrorCode::kFormat, m.path,
             "confidence of frame " + std::to_string(index) +
                 " has NaN, negative or infinite values");
      }
    }
  }
  if (m.meta.has_ground_truth) {
    GroundTruth t;
    m.ReadImage(m.truth_distance, "truth/radial_distance_m", H5T_NATIVE_FLOAT, index,
                t.radial_distance_m);
    m.ReadImage(m.truth_causes, "truth/causes", H5T_NATIVE_UINT16, index, t.causes);
    m.ReadImage(m.truth_sigma, "truth/sigma_m", H5T_NATIVE_FLOAT, index, t.sigma_m);
    for (std::size_t i = 0; i < t.sigma_m.size(); ++i) {
      if (std::isnan(t.radial_distance_m[i]) || !(t.sigma_m[i] >= 0) || std::isinf(t.sigma_m[i])) {
        Fail(ErrorCode::kFormat, m.path,
             "ground truth of frame " + std::to_string(index) + " has NaN or negative values");
      }
    }
    if (m.has_footprint) {
      m.ReadImage(m.truth_near, "truth/footprint_near_m", H5T_NATIVE_FLOAT, index,
                  t.footprint_near_m);
      m.ReadImage(m.truth_far, "truth/footprint_far_m", H5T_NATIVE_FLOAT, index, t.footprint_far_m);
      for (std::size_t i = 0; i < t.footprint_near_m.size(); ++i) {
        const float near = t.footprint_near_m[i], far = t.footprint_far_m[i];
        // Both +inf (nothing hit) or 0 <= near <= far < inf.
        if (!(near >= 0 && near <= far) || (std::isinf(far) && !std::isinf(near))) {
          Fail(ErrorCode::kFormat, m.path,
               "ground-truth footprint of frame " + std::to_string(index) +
                   " is not 0 <= near <= far (or both +inf)");
        }
      }
    }
    frame.truth = std::move(t);
  }
  return frame;
}

std::size_t RecordingReader::IndexAtOrAfter(std::int64_t timestamp_ns) const noexcept {
  const auto& v = impl_->infos;
  const auto it =
      std::lower_bound(v.begin(), v.end(), timestamp_ns,
                       [](const FrameInfo& fi, std::int64_t t) { return fi.timestamp_ns < t; });
  return static_cast<std::size_t>(it - v.begin());
}

// ---------------------------------------------------------------------------------------------
// Playback

PlaybackCamera::PlaybackCamera(const std::filesystem::path& path, const PlaybackOptions& options)
    : reader_(path), options_(options) {
  options_.Validate();
  if (reader_.frame_count() == 0) {
    throw Error(ErrorCode::kFormat, path.string() + ": recording has no frames");
  }
  info_ = reader_.metadata().camera;
  RefreshInfo();
}

const FrameInfo& PlaybackCamera::NextInfo() const {
  return reader_.Info(std::min(next_, reader_.frame_count() - 1));
}

void PlaybackCamera::RefreshInfo() {
  info_.modulation_frequency_hz = NextInfo().modulation_frequency_hz;
}

std::optional<Frame> PlaybackCamera::Grab() {
  if (next_ >= reader_.frame_count()) {
    if (!options_.loop) return std::nullopt;
    next_ = 0;
    start_wall_.reset();
    loop_.Wrap(reader_.Info(0), reader_.Info(reader_.frame_count() - 1), reader_.frame_count());
  }
  Frame frame = reader_.Read(next_);
  if (options_.real_time) {
    const auto now = std::chrono::steady_clock::now();
    if (!start_wall_) {
      start_wall_ = now;
      start_timestamp_ns_ = frame.info.timestamp_ns;
    } else {
      const double offset_ns =
          static_cast<double>(frame.info.timestamp_ns - start_timestamp_ns_) / options_.speed;
      const auto due =
          *start_wall_ + std::chrono::nanoseconds(static_cast<std::int64_t>(offset_ns));
      if (due > now) std::this_thread::sleep_until(due);
    }
  }
  ++next_;
  RefreshInfo();
  loop_.Apply(frame.info);
  return frame;
}

void PlaybackCamera::Seek(std::size_t index) {
  if (index >= reader_.frame_count()) {
    throw Error(ErrorCode::kInvalidArgument, reader_.path().string() + ": seek to frame " +
                                                 std::to_string(index) + " beyond the last frame " +
                                                 std::to_string(reader_.frame_count() - 1));
  }
  next_ = index;
  start_wall_.reset();
  RefreshInfo();
}

void PlaybackCamera::SeekToTimeNs(std::int64_t timestamp_ns) {
  const std::size_t index = reader_.IndexAtOrAfter(timestamp_ns);
  if (index >= reader_.frame_count()) {
    throw Error(ErrorCode::kInvalidArgument,
                reader_.path().string() +
                    ": no frame at or after t = " + std::to_string(timestamp_ns) + " ns");
  }
  Seek(index);
}

namespace {
[[noreturn]] void Unsupported(const std::filesystem::path& path, const std::string& what) {
  throw Error(ErrorCode::kUnsupported,
              path.string() + ": a recording cannot change " + what + " (only the recorded value)");
}
}  // namespace

void PlaybackCamera::SetIntegrationTimeRegister(int reg) {
  if (reg != IntegrationTimeRegister()) {
    Unsupported(reader_.path(), "the integration time to register " + std::to_string(reg));
  }
}
int PlaybackCamera::IntegrationTimeRegister() const { return NextInfo().integration_time_register; }
void PlaybackCamera::SetModulationFrequencyHz(double hz) {
  if (hz != info_.modulation_frequency_hz) {
    Unsupported(reader_.path(), "the modulation frequency to " + std::to_string(hz) + " Hz");
  }
}
void PlaybackCamera::SetDistanceOffsetRegister(int reg) {
  if (reg != DistanceOffsetRegister()) {
    Unsupported(reader_.path(), "the distance offset to " + std::to_string(reg));
  }
}
int PlaybackCamera::DistanceOffsetRegister() const { return NextInfo().distance_offset_register; }
void PlaybackCamera::SetPanAngleRad(double angle_rad) {
  if (angle_rad != PanAngleRad()) {
    Unsupported(reader_.path(), "the pan angle to " + std::to_string(angle_rad) + " rad");
  }
}
double PlaybackCamera::PanAngleRad() const { return NextInfo().pan_angle_rad; }

}  // namespace tofcam

#include "tofcam/io/recording.h"

#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

namespace fs = std::filesystem;

class RecordingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // A parameterised test's name has a '/' ("RecordThenPlayIsBitExact/0"): flattened, so that
    // TearDown removes the whole directory and not only its last component.
    std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    std::replace(name.begin(), name.end(), '/', '_');
    dir_ = fs::temp_directory_path() /
           ("tofcam_recording_test_" + std::to_string(::getpid()) + "_" + name);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

CameraInfo SmallCamera() {
  CameraInfo info;
  info.model = "test-cam";
  info.intrinsics.width = 7;
  info.intrinsics.height = 5;
  info.intrinsics.fx_px = 10.5;
  info.intrinsics.fy_px = 11.25;
  info.intrinsics.cx_px = 3.0;
  info.intrinsics.cy_px = 2.0;
  info.intrinsics.k1 = 0.01;
  info.intrinsics.p2 = -0.002;
  info.modulation_frequency_hz = 20e6;
  return info;
}

// A frame whose every pixel and info field depends on the index and a random stream, so any
// mix-up of frames, channels, rows or columns changes the data.
// `footprint`: the truth carries footprint_near_m / _far_m (recordings made before they existed
// do not).
Frame MakeFrame(const CameraInfo& cam, int index, bool flags, bool truth, std::mt19937& rng,
                bool footprint = true) {
  Frame f;
  const int w = cam.width(), h = cam.height();
  f.distance = Image<std::uint16_t>(w, h);
  f.amplitude = Image<std::uint16_t>(w, h);
  f.intensity = Image<std::uint16_t>(w, h);
  std::uniform_int_distribution<int> u16(0, 65535);
  for (std::size_t i = 0; i < f.distance.size(); ++i) {
    f.distance[i] = static_cast<std::uint16_t>(u16(rng));
    f.amplitude[i] = static_cast<std::uint16_t>(u16(rng));
    f.intensity[i] = static_cast<std::uint16_t>(u16(rng));
  }
  if (flags) {
    f.source_flags = Image<PixelFlags>(w, h);
    for (std::size_t i = 0; i < f.source_flags.size(); ++i) {
      f.source_flags[i] = PixelFlags(static_cast<std::uint16_t>(u16(rng)));
    }
    // A camera's own confidence travels with its flags (the importers of real cameras).
    f.confidence = Image<float>(w, h);
    for (std::size_t i = 0; i < f.confidence.size(); ++i) f.confidence[i] = 0.25f * u16(rng);
    f.info.confidence_source = "test confidence";
  }
  if (truth) {
    GroundTruth t;
    t.radial_distance_m = Image<float>(w, h);
    t.causes = Image<PixelFlags>(w, h);
    t.sigma_m = Image<float>(w, h);
    std::uniform_real_distribution<float> real(0.0f, 7.0f);
    for (std::size_t i = 0; i < t.sigma_m.size(); ++i) {
      t.radial_distance_m[i] = i == 3 ? std::numeric_limits<float>::infinity() : real(rng);
      t.causes[i] = PixelFlags(static_cast<std::uint16_t>(u16(rng) & kTruthMask));
      t.sigma_m[i] = real(rng) * 0.01f;
    }
    if (footprint) {
      t.footprint_near_m = Image<float>(w, h);
      t.footprint_far_m = Image<float>(w, h);
      for (std::size_t i = 0; i < t.footprint_near_m.size(); ++i) {
        const float a = real(rng), b = real(rng);
        t.footprint_near_m[i] = i == 3 ? std::numeric_limits<float>::infinity() : std::min(a, b);
        t.footprint_far_m[i] = i == 3 ? std::numeric_limits<float>::infinity() : std::max(a, b);
      }
    }
    f.truth = std::move(t);
  }
  f.info.sequence = static_cast<std::uint64_t>(index);
  f.info.timestamp_ns = 1'000'000'000LL + index * 33'333'333LL;
  f.info.integration_time_register = 10 + index;
  f.info.integration_time_us = (10 + index) * 255.0;
  f.info.modulation_frequency_hz = 20e6 + index;
  f.info.pan_angle_rad = -0.5 + 0.125 * index;
  f.info.distance_offset_register = 100 * index - 3;
  f.info.camera_model = "test-cam";
  f.info.has_intensity = index % 2 == 0;
  return f;
}

// Writes frames 0..n-1 of MakeFrame (no flags, no truth) to `file`, closed on return; returns
// `file`.
fs::path WriteFrames(const fs::path& file, const CameraInfo& cam, int n, unsigned seed) {
  std::mt19937 rng(seed);
  RecordingWriter writer(file, cam);
  for (int i = 0; i < n; ++i) writer.Append(MakeFrame(cam, i, false, false, rng));
  return file;
}

void ExpectSameFrame(const Frame& a, const Frame& b) {
  EXPECT_EQ(a.distance, b.distance);
  EXPECT_EQ(a.amplitude, b.amplitude);
  EXPECT_EQ(a.intensity, b.intensity);
  EXPECT_EQ(a.source_flags, b.source_flags);
  EXPECT_EQ(a.confidence, b.confidence);
  EXPECT_EQ(a.info.confidence_source, b.info.confidence_source);
  ASSERT_EQ(a.truth.has_value(), b.truth.has_value());
  if (a.truth) {
    EXPECT_EQ(a.truth->radial_distance_m, b.truth->radial_distance_m);
    EXPECT_EQ(a.truth->causes, b.truth->causes);
    EXPECT_EQ(a.truth->sigma_m, b.truth->sigma_m);
    EXPECT_EQ(a.truth->footprint_near_m, b.truth->footprint_near_m);
    EXPECT_EQ(a.truth->footprint_far_m, b.truth->footprint_far_m);
  }
  EXPECT_EQ(a.info.sequence, b.info.sequence);
  EXPECT_EQ(a.info.timestamp_ns, b.info.timestamp_ns);
  EXPECT_EQ(a.info.integration_time_register, b.info.integration_time_register);
  EXPECT_EQ(a.info.integration_time_us, b.info.integration_time_us);
  EXPECT_EQ(a.info.modulation_frequency_hz, b.info.modulation_frequency_hz);
  EXPECT_EQ(a.info.pan_angle_rad, b.info.pan_angle_rad);
  EXPECT_EQ(a.info.distance_offset_register, b.info.distance_offset_register);
  EXPECT_EQ(a.info.camera_model, b.info.camera_model);
  EXPECT_EQ(a.info.has_intensity, b.info.has_intensity);
}

struct RoundTripCase {
  bool flags;
  bool truth;
  int compression;
  bool footprint = true;
};

class RoundTrip : public RecordingTest, public ::testing::WithParamInterface<RoundTripCase> {};

TEST_P(RoundTrip, RecordThenPlayIsBitExact) {
  const RoundTripCase c = GetParam();
  const CameraInfo cam = SmallCamera();
  std::mt19937 rng(42);
  std::vector<Frame> frames;
  for (int i = 0; i < 5; ++i) {
    frames.push_back(MakeFrame(cam, i, c.flags, c.truth, rng, c.footprint));
  }
  const fs::path file = dir_ / "rec.h5";
  RecordingOptions opts;
  opts.compression_level = c.compression;
  opts.calibration_id = "cal-2026-11-22";
  {
    RecordingWriter writer(file, cam, opts);
    for (const Frame& f : frames) writer.Append(f);
    EXPECT_EQ(writer.frame_count(), 5u);
    writer.Close();
  }
  RecordingReader reader(file);
  ASSERT_EQ(reader.frame_count(), 5u);
  const RecordingMetadata& meta = reader.metadata();
  EXPECT_EQ(meta.calibration_id, "cal-2026-11-22");
  EXPECT_EQ(meta.camera.model, "test-cam");
  EXPECT_EQ(meta.camera.intrinsics.fx_px, 10.5);
  EXPECT_EQ(meta.camera.intrinsics.k1, 0.01);
  EXPECT_EQ(meta.camera.intrinsics.p2, -0.002);
  EXPECT_EQ(meta.has_source_flags, c.flags);
  EXPECT_EQ(meta.has_confidence, c.flags);
  EXPECT_EQ(meta.has_ground_truth, c.truth);
  EXPECT_EQ(meta.has_truth_footprint, c.truth && c.footprint);
  for (int i = 4; i >= 0; --i) ExpectSameFrame(reader.Read(static_cast<std::size_t>(i)), frames[i]);

  PlaybackCamera camera(file);
  for (const Frame& f : frames) {
    auto got = camera.Grab();
    ASSERT_TRUE(got.has_value());
    ExpectSameFrame(*got, f);
  }
  EXPECT_FALSE(camera.Grab().has_value());
}

INSTANTIATE_TEST_SUITE_P(Variants, RoundTrip,
                         ::testing::Values(RoundTripCase{false, false, 4},
                                           RoundTripCase{true, false, 0},
                                           RoundTripCase{true, true, 9},
                                           RoundTripCase{false, true, 1},
                                           RoundTripCase{true, true, 2, false}));

TEST_F(RecordingTest, PlaybackSeeksLoopsAndRefusesChanges) {
  const CameraInfo cam = SmallCamera();
  std::mt19937 rng(7);
  const fs::path file = dir_ / "rec.h5";
  std::vector<Frame> frames;
  {
    RecordingWriter writer(file, cam);
    for (int i = 0; i < 4; ++i) {
      frames.push_back(MakeFrame(cam, i, false, false, rng));
      writer.Append(frames.back());
    }
  }  // destructor closes
  PlaybackOptions opts;
  opts.loop = true;
  PlaybackCamera camera(file, opts);
  camera.Seek(2);
  EXPECT_EQ(camera.IntegrationTimeRegister(), 12);
  EXPECT_EQ(camera.Grab()->info.sequence, 2u);
  EXPECT_EQ(camera.Grab()->info.sequence, 3u);
  // Looped: frame 0 again, its sequence number and timestamp continued one frame interval
  // after frame 3 (frames are 33333333 ns apart), its data unchanged.
  const Frame again = *camera.Grab();
  EXPECT_EQ(again.info.sequence, 4u);
  EXPECT_EQ(again.info.timestamp_ns, 1'000'000'000LL + 4 * 33'333'333LL);
  EXPECT_EQ(again.distance, frames[0].distance);
  EXPECT_EQ(camera.Grab()->info.timestamp_ns, 1'000'000'000LL + 5 * 33'333'333LL);
  // Frame 2 has timestamp 1e9 + 2 * 33333333 ns; one ns later selects frame 3.
  camera.SeekToTimeNs(1'000'000'000LL + 2 * 33'333'333LL);
  EXPECT_EQ(camera.position(), 2u);
  camera.SeekToTimeNs(1'000'000'000LL + 2 * 33'333'333LL + 1);
  EXPECT_EQ(camera.position(), 3u);
  camera.SeekToTimeNs(0);
  EXPECT_EQ(camera.position(), 0u);
  EXPECT_THROW(camera.SeekToTimeNs(2'000'000'000LL), Error);
  EXPECT_THROW(camera.Seek(4), Error);

  // The recorded value is accepted; anything else is kUnsupported.
  EXPECT_NO_THROW(camera.SetIntegrationTimeRegister(10));
  try {
    camera.SetIntegrationTimeRegister(11);
    FAIL() << "expected kUnsupported";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kUnsupported);
  }
  EXPECT_EQ(camera.ModulationFrequencyHz(), 20e6);
  EXPECT_NO_THROW(camera.SetModulationFrequencyHz(20e6));
  EXPECT_THROW(camera.SetModulationFrequencyHz(30e6), Error);
  EXPECT_THROW(camera.SetDistanceOffsetRegister(5), Error);
  EXPECT_THROW(camera.SetPanAngleRad(1.0), Error);
  EXPECT_NO_THROW(camera.SetPanAngleRad(-0.5));
}

TEST_F(RecordingTest, ALoopedPlaybackRecordsAgainAndReadsBack) {
  // Recording a looped playback used to write timestamps that start again at each pass, which
  // the reader then refused ("timestamps decrease").
  const CameraInfo cam = SmallCamera();
  PlaybackOptions opts;
  opts.loop = true;
  PlaybackCamera camera(WriteFrames(dir_ / "rec.h5", cam, 3, 5), opts);
  {
    RecordingWriter again(dir_ / "looped.h5", cam);
    for (int i = 0; i < 7; ++i) again.Append(*camera.Grab());
  }
  const RecordingReader reader(dir_ / "looped.h5");
  ASSERT_EQ(reader.frame_count(), 7u);
  for (std::size_t i = 0; i < 7; ++i) {
    EXPECT_EQ(reader.Info(i).timestamp_ns,
              1'000'000'000LL + static_cast<long long>(i) * 33'333'333LL);
    EXPECT_EQ(reader.Info(i).sequence, i);
  }
}

TEST_F(RecordingTest, RealTimePlaybackFollowsTimestamps) {
  // Pacing is checked as a lower bound only (sleeping can overshoot, never undershoot): five
  // frames 33.3 ms apart at speed 2 cannot be served in less than 4 * 16.67 ms.
  PlaybackOptions opts;
  opts.real_time = true;
  opts.speed = 2.0;
  PlaybackCamera camera(WriteFrames(dir_ / "rec.h5", SmallCamera(), 5, 3), opts);
  const auto start = std::chrono::steady_clock::now();
  int n = 0;
  while (camera.Grab()) ++n;
  const auto elapsed = std::chrono::steady_clock::now() - start;
  EXPECT_EQ(n, 5);
  EXPECT_GE(elapsed, std::chrono::nanoseconds(4 * 33'333'333LL / 2));
}

TEST_F(RecordingTest, WriterRejectsInconsistentFrames) {
  const CameraInfo cam = SmallCamera();
  std::mt19937 rng(1);
  RecordingWriter writer(dir_ / "rec.h5", cam);
  writer.Append(MakeFrame(cam, 0, true, false, rng));
  try {
    writer.Append(MakeFrame(cam, 1, false, false, rng));  // lost its source flags
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
  CameraInfo other = cam;
  other.intrinsics.width = 8;
  other.intrinsics.cx_px = 3.5;
  try {
    writer.Append(MakeFrame(other, 1, true, false, rng));
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
  // A timestamp before the previous frame's: the reader would refuse the whole file.
  Frame earlier = MakeFrame(cam, 1, true, false, rng);
  earlier.info.timestamp_ns -= 2 * 33'333'333LL;
  try {
    writer.Append(earlier);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("timestamps may not decrease"), std::string::npos)
        << e.what();
  }
  Frame same_time = MakeFrame(cam, 1, true, false, rng);  // equal timestamps are allowed
  same_time.info.timestamp_ns = MakeFrame(cam, 0, true, false, rng).info.timestamp_ns;
  writer.Append(same_time);
  writer.Close();
  EXPECT_THROW(writer.Append(MakeFrame(cam, 2, true, false, rng)), Error);

  // Truth channels of the wrong size are refused (they would be read past their end), and so
  // is a footprint that comes and goes.
  RecordingWriter truth_writer(dir_ / "truth.h5", cam);
  Frame short_sigma = MakeFrame(cam, 0, false, true, rng);
  short_sigma.truth->sigma_m = Image<float>(2, 2);
  Frame no_sigma = MakeFrame(cam, 0, false, true, rng);
  no_sigma.truth->sigma_m = Image<float>();
  Frame short_far = MakeFrame(cam, 0, false, true, rng);
  short_far.truth->footprint_far_m = Image<float>(cam.width(), 1);
  for (const Frame* f : {&short_sigma, &no_sigma, &short_far}) {
    EXPECT_THROW(truth_writer.Append(*f), Error);
  }
  truth_writer.Append(MakeFrame(cam, 0, false, true, rng));
  try {
    truth_writer.Append(MakeFrame(cam, 1, false, true, rng, false));  // lost its footprint
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
  truth_writer.Close();
  EXPECT_EQ(RecordingReader(dir_ / "truth.h5").frame_count(), 1u);
  EXPECT_EQ(RecordingReader(dir_ / "rec.h5").frame_count(), 2u);
  RecordingOptions bad;
  bad.compression_level = 10;
  EXPECT_THROW(RecordingWriter(dir_ / "bad.h5", cam, bad), Error);
}

ErrorCode CodeOfOpening(const fs::path& file) {
  try {
    RecordingReader reader(file);
    for (std::size_t i = 0; i < reader.frame_count(); ++i) (void)reader.Read(i);
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(file.filename().string()), std::string::npos)
        << "message must name the file: " << e.what();
    return e.code();
  }
  return ErrorCode::kInternal;  // no error at all
}

// What the reader refuses as hostile (frames over 2^22 pixels, a name over 64 KiB) is not
// written: the simulator used to write such files, which tofcam then could not read.
TEST_F(RecordingTest, WriterRefusesWhatTheReaderWouldRefuse) {
  CameraInfo big = SmallCamera();
  big.intrinsics.width = 4096;
  big.intrinsics.height = 1025;
  big.intrinsics.cx_px = 2047.5;
  big.intrinsics.cy_px = 512.0;
  try {
    RecordingWriter writer(dir_ / "big.h5", big);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("4096 x 1025"), std::string::npos) << e.what();
  }
  CameraInfo named = SmallCamera();
  named.model = std::string(70000, 'x');
  EXPECT_THROW(RecordingWriter(dir_ / "named.h5", named), Error);
  EXPECT_FALSE(std::filesystem::exists(dir_ / "big.h5"));
  EXPECT_FALSE(std::filesystem::exists(dir_ / "named.h5"));
  // A calibration id too long: refused before the file is created, so a file already at the
  // path keeps its content.
  { std::ofstream(dir_ / "kept.h5") << "earlier content"; }
  RecordingOptions long_id;
  long_id.calibration_id = std::string(70000, 'c');
  EXPECT_THROW(RecordingWriter(dir_ / "kept.h5", SmallCamera(), long_id), Error);
  EXPECT_EQ(std::filesystem::file_size(dir_ / "kept.h5"), 15u);
  // A first frame whose strings are too long: refused before any dataset exists, so the next
  // frame still starts the recording.
  std::mt19937 rng(3);
  const CameraInfo cam = SmallCamera();
  RecordingWriter writer(dir_ / "first.h5", cam);
  Frame odd = MakeFrame(cam, 0, true, false, rng);
  odd.info.confidence_source = std::string(70000, 's');
  EXPECT_THROW(writer.Append(odd), Error);
  writer.Append(MakeFrame(cam, 0, true, false, rng));
  writer.Close();
  EXPECT_EQ(RecordingReader(dir_ / "first.h5").frame_count(), 1u);
}

TEST_F(RecordingTest, MissingAndNonHdf5FilesAreErrors) {
  EXPECT_EQ(CodeOfOpening(dir_ / "missing.h5"), ErrorCode::kNotFound);
  std::ofstream(dir_ / "text.h5") << "not hdf5 at all";
  EXPECT_EQ(CodeOfOpening(dir_ / "text.h5"), ErrorCode::kFormat);
}

TEST_F(RecordingTest, TruncatedFileIsAnErrorOrFewerFrames) {
  const CameraInfo cam = SmallCamera();
  std::mt19937 rng(5);
  const fs::path file = dir_ / "rec.h5";
  {
    RecordingWriter writer(file, cam);
    for (int i = 0; i < 6; ++i) writer.Append(MakeFrame(cam, i, true, true, rng));
  }
  const auto size = fs::file_size(file);
  // Every truncation point must end in kFormat (or a readable prefix), never a crash.
  for (std::uintmax_t cut : {size / 8, size / 3, size / 2, size - 100, size - 1}) {
    const fs::path cut_file = dir_ / ("cut_" + std::to_string(cut) + ".h5");
    fs::copy_file(file, cut_file);
    fs::resize_file(cut_file, cut);
    const ErrorCode code = CodeOfOpening(cut_file);
    EXPECT_TRUE(code == ErrorCode::kFormat || code == ErrorCode::kInternal)
        << "cut at " << cut << ": " << ErrorCodeName(code);
  }
}

// Builds hostile recordings by editing a valid one with the HDF5 API.
class HostileRecording : public RecordingTest {
 protected:
  fs::path MakeValid() {
    const CameraInfo cam = SmallCamera();
    std::mt19937 rng(9);
    const fs::path file = dir_ / "rec.h5";
    RecordingWriter writer(file, cam);
    for (int i = 0; i < 3; ++i) writer.Append(MakeFrame(cam, i, false, true, rng));
    writer.Close();
    return file;
  }
  template <typename Edit>
  ErrorCode EditAndOpen(Edit edit) {
    const fs::path file = MakeValid();
    const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    EXPECT_GE(f, 0);
    edit(f);
    H5Fclose(f);
    return CodeOfOpening(file);
  }
  static void SetInt(hid_t f, const char* name, std::int64_t v) {
    H5Adelete(f, name);
    const hid_t s = H5Screate(H5S_SCALAR);
    const hid_t a = H5Acreate2(f, name, H5T_STD_I64LE, s, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(a, H5T_NATIVE_INT64, &v);
    H5Aclose(a);
    H5Sclose(s);
  }
  static void SetDouble(hid_t f, const char* name, double v) {
    H5Adelete(f, name);
    const hid_t s = H5Screate(H5S_SCALAR);
    const hid_t a = H5Acreate2(f, name, H5T_IEEE_F64LE, s, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(a, H5T_NATIVE_DOUBLE, &v);
    H5Aclose(a);
    H5Sclose(s);
  }
};

TEST_F(HostileRecording, HugeDimensions) {
  EXPECT_EQ(EditAndOpen([](hid_t f) { SetInt(f, "width", 1 << 20); }), ErrorCode::kFormat);
  EXPECT_EQ(EditAndOpen([](hid_t f) { SetInt(f, "height", -4); }), ErrorCode::kFormat);
  // Size attributes that disagree with the datasets' shape.
  EXPECT_EQ(EditAndOpen([](hid_t f) { SetInt(f, "width", 8); }), ErrorCode::kFormat);
  EXPECT_EQ(EditAndOpen([](hid_t f) { SetInt(f, "frame_count", 1LL << 40); }), ErrorCode::kFormat);
}

TEST_F(HostileRecording, NaNsAndMissingOrWrongDatasets) {
  EXPECT_EQ(EditAndOpen([](hid_t f) { SetDouble(f, "modulation_frequency_hz", NAN); }),
            ErrorCode::kFormat);
  EXPECT_EQ(EditAndOpen([](hid_t f) { H5Ldelete(f, "amplitude", H5P_DEFAULT); }),
            ErrorCode::kFormat);
  EXPECT_EQ(EditAndOpen([](hid_t f) { H5Ldelete(f, "info/timestamp_ns", H5P_DEFAULT); }),
            ErrorCode::kFormat);
  EXPECT_EQ(EditAndOpen([](hid_t f) { H5Adelete(f, "format"); }), ErrorCode::kFormat);
  // A float dataset where uint16 registers belong.
  EXPECT_EQ(EditAndOpen([](hid_t f) {
              H5Ldelete(f, "distance", H5P_DEFAULT);
              const hsize_t dims[3] = {3, 5, 7};
              const hid_t s = H5Screate_simple(3, dims, nullptr);
              const hid_t d = H5Dcreate2(f, "distance", H5T_IEEE_F32LE, s, H5P_DEFAULT, H5P_DEFAULT,
                                         H5P_DEFAULT);
              H5Dclose(d);
              H5Sclose(s);
            }),
            ErrorCode::kFormat);
  // NaN in the per-frame info.
  EXPECT_EQ(EditAndOpen([](hid_t f) {
              const hid_t d = H5Dopen2(f, "info/pan_angle_rad", H5P_DEFAULT);
              const double values[3] = {0.0, NAN, 0.0};
              H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values);
              H5Dclose(d);
            }),
            ErrorCode::kFormat);
  // NaN in the ground truth is found when the frame is read.
  EXPECT_EQ(EditAndOpen([](hid_t f) {
              const hid_t d = H5Dopen2(f, "truth/sigma_m", H5P_DEFAULT);
              std::vector<float> values(3 * 5 * 7, NAN);
              H5Dwrite(d, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data());
              H5Dclose(d);
            }),
            ErrorCode::kFormat);
  // A footprint whose near lies beyond its far, or that is NaN.
  for (const float near : {5.0f, NAN}) {
    EXPECT_EQ(EditAndOpen([near](hid_t f) {
                const hid_t d = H5Dopen2(f, "truth/footprint_near_m", H5P_DEFAULT);
                std::vector<float> values(3 * 5 * 7, near);
                const hid_t far = H5Dopen2(f, "truth/footprint_far_m", H5P_DEFAULT);
                std::vector<float> far_values(3 * 5 * 7, 4.0f);
                H5Dwrite(d, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data());
                H5Dwrite(far, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, far_values.data());
                H5Dclose(d);
                H5Dclose(far);
              }),
              ErrorCode::kFormat);
  }
  // Finite near with infinite far, and the reverse.
  for (const float far : {std::numeric_limits<float>::infinity(), 2.0f}) {
    EXPECT_EQ(EditAndOpen([far](hid_t f) {
                const hid_t n = H5Dopen2(f, "truth/footprint_near_m", H5P_DEFAULT);
                const hid_t d = H5Dopen2(f, "truth/footprint_far_m", H5P_DEFAULT);
                std::vector<float> near_values(3 * 5 * 7, std::isinf(far) ? 1.0f : far + 1.0f);
                if (!std::isinf(far)) {
                  std::fill(near_values.begin(), near_values.end(),
                            std::numeric_limits<float>::infinity());
                }
                std::vector<float> far_values(3 * 5 * 7, far);
                H5Dwrite(n, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, near_values.data());
                H5Dwrite(d, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, far_values.data());
                H5Dclose(n);
                H5Dclose(d);
              }),
              ErrorCode::kFormat);
  }
  // The attribute says there is a footprint but a dataset is missing.
  EXPECT_EQ(EditAndOpen([](hid_t f) { H5Ldelete(f, "truth/footprint_far_m", H5P_DEFAULT); }),
            ErrorCode::kFormat);
}

TEST_F(HostileRecording, FilesWithoutTheFootprintAttributeReadWithoutFootprint) {
  // Files written before the footprint existed have neither the attribute nor the datasets.
  const fs::path file = MakeValid();
  const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  H5Adelete(f, "has_truth_footprint");
  H5Ldelete(f, "truth/footprint_near_m", H5P_DEFAULT);
  H5Ldelete(f, "truth/footprint_far_m", H5P_DEFAULT);
  H5Fclose(f);
  RecordingReader reader(file);
  EXPECT_TRUE(reader.metadata().has_ground_truth);
  EXPECT_FALSE(reader.metadata().has_truth_footprint);
  const Frame frame = reader.Read(2);
  ASSERT_TRUE(frame.truth.has_value());
  EXPECT_FALSE(frame.truth->sigma_m.empty());
  EXPECT_TRUE(frame.truth->footprint_near_m.empty());
  EXPECT_TRUE(frame.truth->footprint_far_m.empty());
}

TEST_F(HostileRecording, FrameCountBeyondDataIsClampedToCompleteFrames) {
  // A recorder killed after extending the datasets but before committing leaves the count
  // attribute lower than the extents; the opposite (count above extents) must be clamped too.
  const fs::path file = MakeValid();
  const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  SetInt(f, "frame_count", 2);
  H5Fclose(f);
  EXPECT_EQ(RecordingReader(file).frame_count(), 2u);
  const hid_t g = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  SetInt(g, "frame_count", 50);
  H5Fclose(g);
  EXPECT_EQ(RecordingReader(file).frame_count(), 3u);
}

// A compressed recording (shuffle + deflate, the default) whose first distance chunk is replaced
// by one that decodes to 8 bytes where a chunk holds 70 (7 x 5 x 2): (a) stored with every
// filter skipped, (b) a valid deflate stream of 8 bytes with the shuffle skipped. libhdf5 1.10
// copied 70 bytes out of the 8-byte result (heap overflow under ASan, found in review); the
// reader decodes chunks itself and must refuse both, naming the dataset. The other frame,
// untouched, still reads exactly.
TEST_F(RecordingTest, ChunksThatDecodeShortAreRefused) {
  const CameraInfo cam = SmallCamera();
  for (int mode = 0; mode < 2; ++mode) {
    std::mt19937 rng(5);
    const fs::path file = dir_ / ("short" + std::to_string(mode) + ".h5");
    std::vector<Frame> frames;
    {
      RecordingWriter writer(file, cam);  // default options: compressed
      for (int i = 0; i < 2; ++i) {
        frames.push_back(MakeFrame(cam, i, false, false, rng));
        writer.Append(frames.back());
      }
    }
    {
      const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
      ASSERT_GE(f, 0);
      const hid_t d = H5Dopen2(f, "distance", H5P_DEFAULT);
      ASSERT_GE(d, 0);
      const std::uint16_t raw[4] = {7, 7, 7, 7};
      const hsize_t offset[3] = {0, 0, 0};
      if (mode == 0) {
        ASSERT_GE(H5Dwrite_chunk(d, H5P_DEFAULT, 0x3, offset, sizeof raw, raw), 0);
      } else {
        unsigned char z[64];
        uLongf z_bytes = sizeof z;
        ASSERT_EQ(compress2(z, &z_bytes, reinterpret_cast<const Bytef*>(raw), sizeof raw, 4), Z_OK);
        ASSERT_GE(H5Dwrite_chunk(d, H5P_DEFAULT, 0x1, offset, z_bytes, z), 0);
      }
      H5Dclose(d);
      H5Fclose(f);
    }
    RecordingReader reader(file);
    try {
      (void)reader.Read(0);
      ADD_FAILURE() << "mode " << mode << ": a chunk of 8 bytes was read as a frame";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kFormat) << e.what();
      EXPECT_NE(std::string(e.what()).find("'distance'"), std::string::npos) << e.what();
    }
    const Frame second = reader.Read(1);
    EXPECT_TRUE(std::equal(second.distance.data(), second.distance.data() + second.distance.size(),
                           frames[1].distance.data()))
        << mode;
  }
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

// Opening and reading every frame of `name` (in tests/data/fuzz) must fail with kFormat, and
// the message must contain `expected`.
void ExpectRefused(const std::string& name, const std::string& expected) {
  const std::filesystem::path p = std::filesystem::path(TOFCAM_TEST_DATA_DIR) / "fuzz" / name;
  try {
    RecordingReader reader(p);
    for (std::size_t i = 0; i < reader.frame_count(); ++i) (void)reader.Read(i);
    ADD_FAILURE() << name << ": a corrupted recording was read without error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFormat) << e.what();
    EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
  }
}

// A fuzzer-found recording whose damaged chunk index makes libhdf5 ask for a 4 GB read buffer.
// The reader must refuse it with a format error before reading.
TEST(HostileRecordingRegression, CorruptedChunkSizesAreRejectedBeforeReading) {
  ExpectRefused("recording_huge_chunk.h5", "recording_huge_chunk.h5");
}

// A fuzzer-found recording (CI run of November 25) whose unfiltered dataset info/timestamp_ns
// stores 8 bytes where its one chunk holds 2048: libhdf5 copied the read's 16 bytes out of an
// 8-byte buffer (a heap overflow under ASan). The reader must refuse it, naming the dataset,
// before any read.
TEST(HostileRecordingRegression, ShortStoredChunksAreRejectedBeforeReading) {
  ExpectRefused("recording_short_chunk.h5",
                "'info/timestamp_ns' stores 8 bytes, not a whole number");
}

}  // namespace
}  // namespace tofcam

#include "tofcam/io/calibration_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

namespace fs = std::filesystem;

fs::path TempDir() {
  return fs::temp_directory_path() / ("tofcam_calfile_" + std::to_string(::getpid()));
}

fs::path Temp(const std::string& name) {
  fs::create_directories(TempDir());
  return TempDir() / name;
}

// Removes the scratch directory after the last test.
class ScratchCleanup : public ::testing::Environment {
 public:
  void TearDown() override {
    std::error_code ignored;
    fs::remove_all(TempDir(), ignored);
  }
};
[[maybe_unused]] ::testing::Environment* const kCleanup =
    ::testing::AddGlobalTestEnvironment(new ScratchCleanup);

OffsetCalibration Sample() {
  OffsetCalibration c;
  c.camera_model = "SR-2";
  c.width = 5;
  c.height = 3;
  c.modulation_frequency_hz = 20e6;
  c.integration_time_us = 5100.0;
  c.integration_time_register = 20;
  c.created_unix_s = 1763780000;
  c.wall_distance_m = 2.0;
  c.wall_normal[0] = 0.1;
  c.wall_normal[1] = 0.0;
  c.wall_normal[2] = std::sqrt(0.99);
  c.frames_averaged = 50;
  c.offset_m = Image<float>(5, 3);
  for (int r = 0; r < 3; ++r)
    for (int col = 0; col < 5; ++col) c.offset_m(r, col) = 0.1f / 3.0f * (r - 1) + 1e-7f * col;
  c.pixel_flags = Image<PixelFlags>(5, 3);
  c.pixel_flags(2, 4) = PixelFlags(Flag::kInvalid);
  c.distance_correction = DistanceCorrection{0.5, 0.05, {0.01f, -0.0123456789f, 0.0f}};
  c.exposure_offset_m_per_ms = 0.0009765625;
  c.noise = NoiseCalibration();
  c.noise->delta_l_scale = 0.1875;
  c.noise->r_squared = 0.8125;
  c.noise->frames = 30;
  c.noise->pixels_used = 19000;
  NoiseModel model;
  model.intercept = -1.5;
  model.log_amplitude = -0.8125;
  model.log_intensity = 0.375;
  model.log_distance = 0.1234567890123;
  model.amplitude_fraction = 0.25;
  model.amplitude_ref = 24381.5;
  model.log_confidence = -0.0625;
  model.log_edge = 0.3125;
  model.edge_ref_m = 0.0078125;
  c.noise->model = model;
  c.noise->model_spearman = 0.875;
  c.noise->eq2_spearman = 0.75;
  c.noise->model_max_decile_error = 0.125;
  ControllerSetpoint sp;
  sp.target_intensity = 28531.25;
  sp.bias_register = 151;
  sp.gain_register_per_intensity = 0.00390625;
  sp.amplitude_max_register = 168;
  sp.amplitude_max_intensity = 31701.5;
  sp.intensity_per_register = 189.5;
  sp.scene = "sim:pavilion";
  c.controller_setpoint = sp;
  ScatteringCalibration sc;
  sc.lobes = {{0.00048828125, 8.0}, {0.000732421875, 48.0}};
  sc.frames = 8;
  sc.integration_time_register = 12;
  sc.target_pixels = 64;
  sc.fit_pixels = 19000;
  sc.explained_fraction = 0.015625;
  c.scattering = sc;
  return c;
}

void ExpectSame(const OffsetCalibration& a, const OffsetCalibration& b) {
  EXPECT_EQ(a.version, b.version);
  EXPECT_EQ(a.camera_model, b.camera_model);
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.modulation_frequency_hz, b.modulation_frequency_hz);
  EXPECT_EQ(a.integration_time_us, b.integration_time_us);
  EXPECT_EQ(a.integration_time_register, b.integration_time_register);
  EXPECT_EQ(a.created_unix_s, b.created_unix_s);
  EXPECT_EQ(a.wall_distance_m, b.wall_distance_m);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(a.wall_normal[k], b.wall_normal[k]);
  EXPECT_EQ(a.frames_averaged, b.frames_averaged);
  EXPECT_TRUE(a.offset_m == b.offset_m);  // bit-exact floats
  EXPECT_TRUE(a.pixel_flags == b.pixel_flags);
  ASSERT_EQ(a.distance_correction.has_value(), b.distance_correction.has_value());
  if (a.distance_correction) {
    EXPECT_EQ(a.distance_correction->start_m, b.distance_correction->start_m);
    EXPECT_EQ(a.distance_correction->step_m, b.distance_correction->step_m);
    EXPECT_EQ(a.distance_correction->correction_m, b.distance_correction->correction_m);
  }
  EXPECT_EQ(a.exposure_offset_m_per_ms, b.exposure_offset_m_per_ms);
  ASSERT_EQ(a.noise.has_value(), b.noise.has_value());
  if (a.noise) {
    EXPECT_EQ(a.noise->delta_l_scale, b.noise->delta_l_scale);
    EXPECT_EQ(a.noise->r_squared, b.noise->r_squared);
    EXPECT_EQ(a.noise->frames, b.noise->frames);
    EXPECT_EQ(a.noise->pixels_used, b.noise->pixels_used);
    ASSERT_EQ(a.noise->model.has_value(), b.noise->model.has_value());
    if (a.noise->model) {
      const NoiseModel &x = *a.noise->model, &y = *b.noise->model;
      EXPECT_EQ(x.intercept, y.intercept);
      EXPECT_EQ(x.log_amplitude, y.log_amplitude);
      EXPECT_EQ(x.log_intensity, y.log_intensity);
      EXPECT_EQ(x.log_distance, y.log_distance);
      EXPECT_EQ(x.amplitude_fraction, y.amplitude_fraction);
      EXPECT_EQ(x.amplitude_ref, y.amplitude_ref);
      EXPECT_EQ(x.log_confidence, y.log_confidence);
      EXPECT_EQ(x.log_edge, y.log_edge);
      EXPECT_EQ(x.edge_ref_m, y.edge_ref_m);
      EXPECT_EQ(a.noise->model_spearman, b.noise->model_spearman);
      EXPECT_EQ(a.noise->eq2_spearman, b.noise->eq2_spearman);
      EXPECT_EQ(a.noise->model_max_decile_error, b.noise->model_max_decile_error);
    }
  }
  ASSERT_EQ(a.controller_setpoint.has_value(), b.controller_setpoint.has_value());
  if (a.controller_setpoint) {
    const ControllerSetpoint &x = *a.controller_setpoint, &y = *b.controller_setpoint;
    EXPECT_EQ(x.target_intensity, y.target_intensity);
    EXPECT_EQ(x.bias_register, y.bias_register);
    EXPECT_EQ(x.gain_register_per_intensity, y.gain_register_per_intensity);
    EXPECT_EQ(x.amplitude_max_register, y.amplitude_max_register);
    EXPECT_EQ(x.amplitude_max_intensity, y.amplitude_max_intensity);
    EXPECT_EQ(x.intensity_per_register, y.intensity_per_register);
    EXPECT_EQ(x.scene, y.scene);
  }
  ASSERT_EQ(a.scattering.has_value(), b.scattering.has_value());
  if (a.scattering) {
    const ScatteringCalibration &x = *a.scattering, &y = *b.scattering;
    ASSERT_EQ(x.lobes.size(), y.lobes.size());
    for (std::size_t k = 0; k < x.lobes.size(); ++k) {
      EXPECT_EQ(x.lobes[k].weight, y.lobes[k].weight);
      EXPECT_EQ(x.lobes[k].sigma_px, y.lobes[k].sigma_px);
    }
    EXPECT_EQ(x.frames, y.frames);
    EXPECT_EQ(x.integration_time_register, y.integration_time_register);
    EXPECT_EQ(x.target_pixels, y.target_pixels);
    EXPECT_EQ(x.fit_pixels, y.fit_pixels);
    EXPECT_EQ(x.explained_fraction, y.explained_fraction);
  }
}

TEST(CalibrationFileTest, RoundTripIsExact) {
  const fs::path p = Temp("round.yaml");
  const OffsetCalibration c = Sample();
  SaveCalibration(p, c);
  ExpectSame(LoadCalibration(p), c);
  // Without the optional parts.
  OffsetCalibration plain = Sample();
  plain.pixel_flags = Image<PixelFlags>();
  plain.distance_correction.reset();
  plain.noise.reset();
  plain.controller_setpoint.reset();
  plain.scattering.reset();
  SaveCalibration(p, plain);
  ExpectSame(LoadCalibration(p), plain);
  // Written atomically: no temporary file left beside the target.
  for (const auto& entry : fs::directory_iterator(p.parent_path())) {
    EXPECT_EQ(entry.path().string().find(".tmp-"), std::string::npos) << entry.path();
  }
}

TEST(CalibrationFileTest, FileIsTheDocumentedYaml) {
  const fs::path p = Temp("doc.yaml");
  SaveCalibration(p, Sample());
  const std::string text = ReadFile(p);
  for (const char* key :
       {"format: tofcam-calibration", "version: 3", "camera_model: \"SR-2\"", "width: 5",
        "height: 3", "modulation_frequency_hz: 20000000", "uncalibrated_pixels: [[2, 4]]",
        "distance_correction:", "exposure_offset_m_per_ms: 0.0009765625",
        "noise:", "delta_l_scale: 0.1875", "controller_setpoint:", "bias_register: 151",
        "scene: \"sim:pavilion\"", "scattering:", "- {weight: 0.00048828125, sigma_px: 8}",
        "integration_time_register: 12"}) {
    EXPECT_NE(text.find(key), std::string::npos) << key << "\n" << text;
  }
}

TEST(CalibrationFileTest, SaveRejectsInvalidCalibration) {
  OffsetCalibration c = Sample();
  c.offset_m(0, 0) = NAN;
  EXPECT_THROW(SaveCalibration(Temp("bad.yaml"), c), Error);
  EXPECT_FALSE(fs::exists(Temp("bad.yaml")));
}

TEST(CalibrationFileTest, MissingFileIsNotFound) {
  try {
    (void)LoadCalibration(Temp("does-not-exist.yaml"));
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kNotFound);
  }
}

// Saves Sample(), replaces `from` by `to` in the text, loads, and returns the kFormat message.
std::string LoadEdited(const std::string& from, const std::string& to) {
  const fs::path p = Temp("edited.yaml");
  SaveCalibration(p, Sample());
  std::string text = ReadFile(p);
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << "test setup: '" << from << "' not in\n" << text;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  WriteFileAtomically(p, text);
  try {
    (void)LoadCalibration(p);
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFormat) << e.what();
    EXPECT_NE(std::string(e.what()).find("edited.yaml"), std::string::npos) << e.what();
    return e.what();
  }
  return "loaded without error";
}

void ExpectRejected(const std::string& from, const std::string& to, const std::string& needle) {
  const std::string message = LoadEdited(from, to);
  EXPECT_NE(message.find(needle), std::string::npos)
      << "edit '" << from << "' -> '" << to << "': " << message;
}

TEST(CalibrationFileTest, RejectsEveryMalformedField) {
  ExpectRejected("format: tofcam-calibration", "format: something-else", "format is");
  ExpectRejected("format: tofcam-calibration\n", "", "missing key 'format'");
  ExpectRejected("version: 3", "version: 4", "unsupported version 4");
  ExpectRejected("version: 3", "version: 0", "unsupported version 0");
  ExpectRejected("version: 3", "version: one", "not an integer");
  // Older versions cannot carry the later keys (the Sample has all of them).
  ExpectRejected("version: 3", "version: 1", "unknown key 'exposure_offset_m_per_ms'");
  ExpectRejected("version: 3", "version: 2", "unknown key 'scattering'");
  ExpectRejected("- {weight: 0.00048828125", "- {weight: 0.7", "weight");
  ExpectRejected("- {weight: 0.00048828125", "- {weight: nan", "not finite");
  ExpectRejected("sigma_px: 48}", "sigma_px: 0}", "sigma");
  ExpectRejected("sigma_px: 48}", "sigma_px: 48, gain: 2}", "unknown key 'gain'");
  ExpectRejected("explained_fraction: 0.015625", "explained_fraction: 2", "[0, 1]");
  ExpectRejected("  target_pixels: 64\n", "", "missing key 'target_pixels'");
  ExpectRejected("exposure_offset_m_per_ms: 0.0009765625\n", "",
                 "missing key 'exposure_offset_m_per_ms'");
  ExpectRejected("exposure_offset_m_per_ms: 0.0009765625", "exposure_offset_m_per_ms: 0.5",
                 "beyond ±0.1 m/ms");
  ExpectRejected("exposure_offset_m_per_ms: 0.0009765625", "exposure_offset_m_per_ms: nan",
                 "not finite");
  ExpectRejected("delta_l_scale: 0.1875", "delta_l_scale: 0", "must be in (0, 1e6]");
  ExpectRejected("delta_l_scale: 0.1875", "delta_l_scale: -1", "must be in (0, 1e6]");
  ExpectRejected("  delta_l_scale: 0.1875\n", "", "missing key 'delta_l_scale'");
  ExpectRejected("pixels_used: 19000", "pixels_used: 19000\n  sigma: 1", "unknown key 'sigma'");
  // A repeated key would otherwise leave the first value in place without a word.
  ExpectRejected("width: 5", "width: 5\nwidth: 999", "key 'width' appears twice");
  ExpectRejected("delta_l_scale: 0.1875", "delta_l_scale: 0.1875\n  delta_l_scale: 7",
                 "key 'delta_l_scale' appears twice");
  ExpectRejected("log_amplitude: -0.8125", "log_amplitude: 5000", "within +-1e3");
  ExpectRejected("log_amplitude: -0.8125", "log_amplitude: .nan", "log_amplitude");
  ExpectRejected("amplitude_ref: 24381.5", "amplitude_ref: 0", "amplitude_ref");
  ExpectRejected("    log_confidence: -0.0625\n", "", "missing key 'log_confidence'");
  ExpectRejected("log_confidence: -0.0625", "log_confidence: -0.0625\n    slope: 1",
                 "unknown key 'slope'");
  ExpectRejected("held_out_spearman: 0.875", "held_out_spearman: 2", "spearman");
  ExpectRejected("edge_ref_m: 0.0078125", "edge_ref_m: 0", "edge_ref_m");
  ExpectRejected("log_edge: 0.3125", "log_edge: .nan", "log_edge");
  // Files written before the edge channel have neither key: no edge term.
  {
    const fs::path p = Temp("no_edge.yaml");
    SaveCalibration(p, Sample());
    std::string text = ReadFile(p);
    for (const std::string key : {"    log_edge: 0.3125\n", "    edge_ref_m: 0.0078125\n"}) {
      const auto at = text.find(key);
      ASSERT_NE(at, std::string::npos) << text;
      text.erase(at, key.size());
    }
    WriteFileAtomically(p, text);
    const OffsetCalibration old = LoadCalibration(p);
    ASSERT_TRUE(old.noise && old.noise->model);
    EXPECT_EQ(old.noise->model->log_edge, 0.0);
    EXPECT_FALSE(old.noise->model->uses_edges());
  }
  ExpectRejected("bias_register: 151", "bias_register: 0", "bias_register = 0 is outside");
  ExpectRejected("target_intensity: 28531.25", "target_intensity: 70000", "(0, 65532]");
  ExpectRejected("gain_register_per_intensity: 0.00390625", "gain_register_per_intensity: 2",
                 "must be in [0, 1]");
  ExpectRejected("  scene: \"sim:pavilion\"\n", "", "missing key 'scene'");
  ExpectRejected("width: 5", "width: 0", "width = 0 is outside");
  ExpectRejected("width: 5", "width: 4", "offset_m row 0 has 5 entries, expected 4");
  ExpectRejected("width: 5", "width: 100000", "width = 100000 is outside");
  ExpectRejected("width: 5\nheight: 3", "width: 16384\nheight: 16384", "exceeds 2^24 pixels");
  ExpectRejected("height: 3", "height: 4", "offset_m has 3 entries, expected 4");
  ExpectRejected("height: 3", "height: -3", "outside");
  ExpectRejected("modulation_frequency_hz: 20000000", "modulation_frequency_hz: 0", "> 0");
  ExpectRejected("modulation_frequency_hz: 20000000", "modulation_frequency_hz: 30000000x",
                 "not a number");
  ExpectRejected("camera_model: \"SR-2\"\n", "", "missing key 'camera_model'");
  ExpectRejected("frames_averaged: 50", "frames_averaged: 50\nbogus_key: 1",
                 "unknown key 'bogus_key'");
  ExpectRejected("wall_normal: [", "wall_normal: [7, ", "wall_normal has 4 entries");
  ExpectRejected("offset_m:\n  - [", "offset_m:\n  - [.nan, ", "row 0 has 6 entries");
  const std::string first = "offset_m:\n  - [-0.0333333351,";
  ExpectRejected(first, "offset_m:\n  - [.nan,", "row 0, col 0 = '.nan' is not");
  ExpectRejected(first, "offset_m:\n  - [nan,", "row 0, col 0 = 'nan' is not finite");
  ExpectRejected(first, "offset_m:\n  - [inf,", "not finite");
  ExpectRejected(first, "offset_m:\n  - [abc,", "not a number");
  ExpectRejected(first, "offset_m:\n  - [1e999,", "not a number");  // overflows a double
  ExpectRejected(first, "offset_m:\n  - [3.9,", "beyond ±L/2");
  ExpectRejected(first, "offset_m:\n  - [[1],", "must be a number");
  ExpectRejected("uncalibrated_pixels: [[2, 4]]", "uncalibrated_pixels: [[3, 4]]",
                 "row = 3 is outside [0, 2]");
  ExpectRejected("uncalibrated_pixels: [[2, 4]]", "uncalibrated_pixels: [[2]]",
                 "has 1 entries, expected 2");
  ExpectRejected("step_m: 0.050000000000000003", "step_m: 0", "step_m = 0 must be > 0");
  ExpectRejected("step_m: 0.050000000000000003", "step_m: 0.05\n  extra: 1", "unknown key 'extra'");
  ExpectRejected("correction_m: [", "correction_m: [nan, ", "not finite");
  ExpectRejected("format: tofcam-calibration", "format: [unclosed", "not valid YAML");
}

TEST(CalibrationFileTest, VersionOneFilesLoadWithoutExposureCompensation) {
  // A version-1 file as the previous build wrote it: no exposure offset, noise or set point.
  OffsetCalibration v1 = Sample();
  v1.exposure_offset_m_per_ms = 0.0;
  v1.noise.reset();
  v1.controller_setpoint.reset();
  v1.scattering.reset();
  const fs::path p = Temp("v1.yaml");
  SaveCalibration(p, v1);
  std::string text = ReadFile(p);
  for (const auto& [from, to] : {std::pair<std::string, std::string>{"version: 3", "version: 1"},
                                 {"exposure_offset_m_per_ms: 0\n", ""}}) {
    const auto at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from << "\n" << text;
    text.replace(at, from.size(), to);
  }
  WriteFileAtomically(p, text);
  const OffsetCalibration loaded = LoadCalibration(p);
  EXPECT_EQ(loaded.version, OffsetCalibration::kVersion);  // upgraded in memory
  EXPECT_EQ(loaded.exposure_offset_m_per_ms, 0.0);
  EXPECT_FALSE(loaded.noise.has_value());
  EXPECT_FALSE(loaded.controller_setpoint.has_value());
  ExpectSame(loaded, v1);
}

TEST(CalibrationFileTest, RejectsNonMappingsAndEmptyFiles) {
  const fs::path p = Temp("junk.yaml");
  for (const char* text : {"", "just a string", "- 1\n- 2\n", "\x01\x02\xff"}) {
    WriteFileAtomically(p, text);
    try {
      (void)LoadCalibration(p);
      ADD_FAILURE() << "loaded '" << text << "'";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kFormat) << e.what();
    }
  }
}

TEST(CalibrationFileTest, MismatchNamesTheField) {
  const OffsetCalibration c = Sample();
  CameraInfo info;
  info.model = "SR-2";
  info.intrinsics.width = 5;
  info.intrinsics.height = 3;
  EXPECT_NO_THROW(CheckCalibrationMatches(c, info));
  const auto message = [&](const CameraInfo& i) {
    try {
      CheckCalibrationMatches(c, i);
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kMismatch);
      return std::string(e.what());
    }
    return std::string("matched");
  };
  CameraInfo other = info;
  other.model = "SR-3000";
  EXPECT_NE(message(other).find("camera model"), std::string::npos);
  other = info;
  other.intrinsics.width = 176;
  EXPECT_NE(message(other).find("width is 5"), std::string::npos);
  other = info;
  other.intrinsics.height = 144;
  EXPECT_NE(message(other).find("height is 3"), std::string::npos);
  other = info;
  other.modulation_frequency_hz = 30e6;
  EXPECT_NE(message(other).find("modulation frequency"), std::string::npos);
}

}  // namespace
}  // namespace tofcam

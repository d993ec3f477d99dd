#include "tofcam/io/pipeline_config.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

namespace fs = std::filesystem;

// Every field of the options that the file carries, compared one by one (a missed field in the
// writer or the reader shows up here as a difference after the round trip).
void ExpectSameOptions(const PipelineOptions& a, const PipelineOptions& b) {
  EXPECT_EQ(a.metric.remove_distance_offset_register, b.metric.remove_distance_offset_register);
  EXPECT_EQ(a.calibration_file, b.calibration_file);
  EXPECT_EQ(a.accuracy_enabled, b.accuracy_enabled);
  EXPECT_EQ(a.accuracy.scale, b.accuracy.scale);
  EXPECT_EQ(a.accuracy.intensity_per_amplitude, b.accuracy.intensity_per_amplitude);
  const FilterSetOptions& fa = a.filters;
  const FilterSetOptions& fb = b.filters;
  EXPECT_EQ(fa.range_enabled, fb.range_enabled);
  EXPECT_EQ(fa.range.min_distance_m, fb.range.min_distance_m);
  EXPECT_EQ(fa.range.max_distance_m, fb.range.max_distance_m);
  EXPECT_EQ(fa.amplitude_enabled, fb.amplitude_enabled);
  EXPECT_EQ(fa.amplitude.min_amplitude, fb.amplitude.min_amplitude);
  EXPECT_EQ(fa.saturation_enabled, fb.saturation_enabled);
  EXPECT_EQ(fa.saturation.max_intensity, fb.saturation.max_intensity);
  EXPECT_EQ(fa.saturation.max_amplitude, fb.saturation.max_amplitude);
  EXPECT_EQ(fa.saturation.max_peak, fb.saturation.max_peak);
  EXPECT_EQ(fa.accuracy_enabled, fb.accuracy_enabled);
  EXPECT_EQ(fa.accuracy.max_delta_l_m, fb.accuracy.max_delta_l_m);
  EXPECT_EQ(fa.flying_pixel_enabled, fb.flying_pixel_enabled);
  EXPECT_EQ(fa.flying_pixel.min_amplitude_contrast, fb.flying_pixel.min_amplitude_contrast);
  EXPECT_EQ(fa.flying_pixel.amplitude_mean_floor, fb.flying_pixel.amplitude_mean_floor);
  EXPECT_EQ(fa.flying_pixel.min_close_delta_m, fb.flying_pixel.min_close_delta_m);
  EXPECT_EQ(fa.flying_pixel.min_far_delta_m, fb.flying_pixel.min_far_delta_m);
  EXPECT_EQ(fa.flying_pixel.min_max_delta_m, fb.flying_pixel.min_max_delta_m);
  EXPECT_EQ(fa.flying_pixel.min_avg_delta_m, fb.flying_pixel.min_avg_delta_m);
  EXPECT_EQ(fa.jump_edge_enabled, fb.jump_edge_enabled);
  EXPECT_EQ(fa.jump_edge.max_angle_deg, fb.jump_edge.max_angle_deg);
  EXPECT_EQ(fa.weingarten_enabled, fb.weingarten_enabled);
  EXPECT_EQ(fa.weingarten.voxel_size_m, fb.weingarten.voxel_size_m);
  EXPECT_EQ(fa.weingarten.min_points, fb.weingarten.min_points);
  const ControllerOptions& ca = a.controller;
  const ControllerOptions& cb = b.controller;
  EXPECT_EQ(a.controller_enabled, b.controller_enabled);
  EXPECT_EQ(ca.kind, cb.kind);
  EXPECT_EQ(ca.target_intensity, cb.target_intensity);
  EXPECT_EQ(ca.gain_register_per_intensity, cb.gain_register_per_intensity);
  EXPECT_EQ(ca.bias_register, cb.bias_register);
  EXPECT_EQ(ca.min_register, cb.min_register);
  EXPECT_EQ(ca.max_register, cb.max_register);
  EXPECT_EQ(ca.roi.row, cb.roi.row);
  EXPECT_EQ(ca.roi.col, cb.roi.col);
  EXPECT_EQ(ca.roi.rows, cb.roi.rows);
  EXPECT_EQ(ca.roi.cols, cb.roi.cols);
  EXPECT_EQ(ca.exclude_flags, cb.exclude_flags);
  EXPECT_EQ(ca.clipped_intensity, cb.clipped_intensity);
  EXPECT_EQ(ca.percent_over_pos, cb.percent_over_pos);
  EXPECT_EQ(ca.desired_pos, cb.desired_pos);
  EXPECT_EQ(ca.vendor_gain, cb.vendor_gain);
  EXPECT_EQ(ca.vendor_max_step_register, cb.vendor_max_step_register);
  EXPECT_EQ(ca.vendor_deadband, cb.vendor_deadband);
  EXPECT_EQ(ca.loop_gain, cb.loop_gain);
  EXPECT_EQ(ca.frame_rate_hz, cb.frame_rate_hz);
  EXPECT_EQ(a.uncertainty_enabled, b.uncertainty_enabled);
  EXPECT_EQ(a.uncertainty.max_uncertainty_m, b.uncertainty.max_uncertainty_m);
  EXPECT_EQ(a.uncertainty.edge_fraction, b.uncertainty.edge_fraction);
  EXPECT_EQ(a.uncertainty.min_jump_sigma, b.uncertainty.min_jump_sigma);
  EXPECT_EQ(a.uncertainty.extrapolate_edges, b.uncertainty.extrapolate_edges);
  EXPECT_EQ(a.uncertainty.unmix_edges, b.uncertainty.unmix_edges);
  EXPECT_EQ(a.uncertainty.unknown_neighbour_flags, b.uncertainty.unknown_neighbour_flags);
  EXPECT_EQ(a.uncertainty.judge_combination, b.uncertainty.judge_combination);
  EXPECT_EQ(a.prediction_enabled, b.prediction_enabled);
  EXPECT_EQ(a.prediction.radius_px, b.prediction.radius_px);
  EXPECT_EQ(a.prediction.max_disagreement_sigma, b.prediction.max_disagreement_sigma);
  EXPECT_EQ(a.prediction.min_pairs, b.prediction.min_pairs);
  EXPECT_EQ(a.prediction_combine, b.prediction_combine);
  EXPECT_EQ(a.denoise_enabled, b.denoise_enabled);
  EXPECT_EQ(a.denoise.radius_px, b.denoise.radius_px);
  EXPECT_EQ(a.denoise.support_sigma, b.denoise.support_sigma);
  EXPECT_EQ(a.denoise.max_step_m, b.denoise.max_step_m);
  EXPECT_EQ(a.denoise.fit_plane, b.denoise.fit_plane);
  EXPECT_EQ(a.frame_pair_enabled, b.frame_pair_enabled);
  EXPECT_EQ(a.alternate_modulation_frequency_hz, b.alternate_modulation_frequency_hz);
  EXPECT_EQ(a.hdr_exposure_ratio, b.hdr_exposure_ratio);
  EXPECT_EQ(a.frame_pair.max_range_m, b.frame_pair.max_range_m);
  EXPECT_EQ(a.frame_pair.max_disagreement_sigma, b.frame_pair.max_disagreement_sigma);
  EXPECT_EQ(a.frame_pair.min_tolerance_m, b.frame_pair.min_tolerance_m);
  EXPECT_EQ(a.frame_pair.max_amplitude_ratio, b.frame_pair.max_amplitude_ratio);
  EXPECT_EQ(a.frame_pair.max_amplitude_disagreement_sigma,
            b.frame_pair.max_amplitude_disagreement_sigma);
  EXPECT_EQ(a.frame_pair.min_amplitude_tolerance, b.frame_pair.min_amplitude_tolerance);
  EXPECT_EQ(a.frame_pair.max_motion_m, b.frame_pair.max_motion_m);
  EXPECT_EQ(a.frame_pair.two_returns_radius_px, b.frame_pair.two_returns_radius_px);
  EXPECT_EQ(a.smoothing_enabled, b.smoothing_enabled);
  EXPECT_EQ(a.smoothing.kind, b.smoothing.kind);
  EXPECT_EQ(a.smoothing.radius_px, b.smoothing.radius_px);
  EXPECT_EQ(a.smoothing.max_jump_m, b.smoothing.max_jump_m);
  EXPECT_EQ(a.smoothing.min_support, b.smoothing.min_support);
  EXPECT_EQ(a.smoothing.range_sigma_factor, b.smoothing.range_sigma_factor);
  EXPECT_EQ(a.smoothing.fallback_sigma_m, b.smoothing.fallback_sigma_m);
  EXPECT_EQ(a.temporal_enabled, b.temporal_enabled);
  EXPECT_EQ(a.temporal.reset_sigma, b.temporal.reset_sigma);
  EXPECT_EQ(a.temporal.max_frames, b.temporal.max_frames);
  EXPECT_EQ(a.temporal.drift_sigma, b.temporal.drift_sigma);
  EXPECT_EQ(a.temporal.drift_frames, b.temporal.drift_frames);
  EXPECT_EQ(a.temporal.max_gap_frames, b.temporal.max_gap_frames);
  EXPECT_EQ(a.temporal.fallback_sigma_m, b.temporal.fallback_sigma_m);
  EXPECT_EQ(a.cloud_enabled, b.cloud_enabled);
  EXPECT_EQ(a.cloud.nan_mask, b.cloud.nan_mask);
  EXPECT_EQ(a.color.near_m, b.color.near_m);
  EXPECT_EQ(a.color.far_m, b.color.far_m);
  EXPECT_EQ(a.color.out_of_range_black, b.color.out_of_range_black);
  EXPECT_EQ(a.color.amplitude_shading, b.color.amplitude_shading);
  EXPECT_EQ(a.color.shading_reference_amplitude, b.color.shading_reference_amplitude);
  EXPECT_EQ(a.color.shading_min_value, b.color.shading_min_value);
  EXPECT_EQ(a.color_legend, b.color_legend);
  EXPECT_EQ(a.stats.bad_error_m, b.stats.bad_error_m);
}

// Options that differ from the defaults in every field, with values that have no short decimal
// form (0.1 + 0.2, 1/3) so that a lossy number format would break the round trip.
PipelineOptions Unusual() {
  PipelineOptions o;
  o.metric.remove_distance_offset_register = false;
  o.calibration_file = "cal \"wall\" \\ 2.yaml";
  o.accuracy.scale = 1.0 / 3.0;
  o.accuracy.intensity_per_amplitude = 0.1 + 0.2;
  o.filters.range_enabled = true;
  o.filters.range.min_distance_m = 0.25;
  o.filters.range.max_distance_m = 6.9;
  o.filters.amplitude_enabled = true;
  o.filters.amplitude.min_amplitude = 123.5;
  o.filters.saturation_enabled = false;
  o.filters.saturation.max_intensity = 60000;
  o.filters.saturation.max_amplitude = 50000;
  o.filters.saturation.max_peak = 61000.25;
  o.filters.accuracy.max_delta_l_m = 0.045;
  o.filters.flying_pixel_enabled = true;
  o.filters.flying_pixel.min_amplitude_contrast = 0.07;
  o.filters.flying_pixel.amplitude_mean_floor = 40;
  o.filters.flying_pixel.min_close_delta_m = 0.06;
  o.filters.flying_pixel.min_far_delta_m = 0.04;
  o.filters.flying_pixel.min_max_delta_m = 0.12;
  o.filters.flying_pixel.min_avg_delta_m = 0.01;
  o.filters.jump_edge_enabled = true;
  o.filters.jump_edge.max_angle_deg = 155;
  o.filters.weingarten_enabled = true;
  o.filters.weingarten.voxel_size_m = 0.2;
  o.filters.weingarten.min_points = 7;
  o.controller_enabled = false;
  o.controller.kind = ControllerKind::kVendorHistogram;
  o.controller.target_intensity = 17000;
  o.controller.gain_register_per_intensity = 1e-5;
  o.controller.bias_register = 50;
  o.controller.min_register = 2;
  o.controller.max_register = 200;
  o.controller.roi = {10, 20, 30, 40};
  o.controller.exclude_flags = (PixelFlags(Flag::kInvalid) | Flag::kSaturated).bits();
  o.controller.clipped_intensity = 60000.5;
  o.controller.percent_over_pos = 12.5;
  o.controller.desired_pos = 60;
  o.controller.vendor_gain = 0.75;
  o.controller.vendor_max_step_register = 5;
  o.controller.vendor_deadband = 3;
  o.controller.loop_gain = 1.0 / 3;
  o.controller.frame_rate_hz = 12.5;
  o.uncertainty_enabled = true;
  o.uncertainty.max_uncertainty_m = 0.04;
  o.uncertainty.edge_fraction = 0.25;
  o.uncertainty.min_jump_sigma = 2.5;
  o.uncertainty.extrapolate_edges = true;
  o.uncertainty.unmix_edges = true;
  o.uncertainty.unknown_neighbour_flags = PixelFlags(Flag::kSaturated).bits();
  o.uncertainty.judge_combination = true;
  o.prediction_enabled = true;
  o.prediction.radius_px = 2;
  o.prediction.max_disagreement_sigma = 3.5;
  o.prediction.min_pairs = 5;
  o.prediction_combine = true;
  o.denoise_enabled = false;  // excludes the prediction: its flag round-trips in the test below
  o.denoise.radius_px = 2;
  o.denoise.support_sigma = 2.5;
  o.denoise.max_step_m = 0.2;
  o.denoise.fit_plane = true;
  o.frame_pair_enabled = true;
  o.alternate_modulation_frequency_hz = 17e6;
  o.frame_pair.max_range_m = 40.0;
  o.frame_pair.max_disagreement_sigma = 3.5;
  o.frame_pair.min_tolerance_m = 0.02;
  o.frame_pair.max_amplitude_ratio = 1.5;
  o.frame_pair.max_amplitude_disagreement_sigma = 2.5;
  o.frame_pair.min_amplitude_tolerance = 0.03;
  o.frame_pair.max_motion_m = 0.1;
  o.frame_pair.two_returns_radius_px = 2;
  o.smoothing_enabled = true;
  o.smoothing.kind = SpatialFilterKind::kBilateral;
  o.smoothing.radius_px = 2;
  o.smoothing.max_jump_m = 0.1 + 0.2;
  o.smoothing.min_support = 5;
  o.smoothing.range_sigma_factor = 2.5;
  o.smoothing.fallback_sigma_m = 0.03;
  o.temporal_enabled = true;
  o.temporal.reset_sigma = 4.5;
  o.temporal.max_frames = 12;
  o.temporal.drift_sigma = 1.25;
  o.temporal.drift_frames = 4;
  o.temporal.max_gap_frames = 3;
  o.temporal.fallback_sigma_m = 0.015;
  o.cloud_enabled = false;
  o.cloud.nan_mask = 0;
  o.color.near_m = 0.5;
  o.color.far_m = 5.0;
  o.color.out_of_range_black = true;
  o.color.amplitude_shading = true;
  o.color.shading_reference_amplitude = 9000;
  o.color.shading_min_value = 0.1;
  o.color_legend = false;
  o.stats.bad_error_m = 0.03;
  return o;
}

TEST(PipelineConfigTest, DefaultsRoundTrip) {
  const PipelineOptions defaults;
  const std::string text = PipelineConfigToYaml(defaults);
  const PipelineOptions back = ParsePipelineConfig(text, "defaults");
  ExpectSameOptions(defaults, back);
}

TEST(PipelineConfigTest, EveryFieldRoundTrips) {
  const PipelineOptions o = Unusual();
  const PipelineOptions back = ParsePipelineConfig(PipelineConfigToYaml(o), "unusual");
  ExpectSameOptions(o, back);
  // Guard against a vacuous comparison: the unusual options really differ from the defaults.
  EXPECT_NE(back.accuracy.scale, PipelineOptions{}.accuracy.scale);
  EXPECT_EQ(back.controller.kind, ControllerKind::kVendorHistogram);
}

TEST(PipelineConfigTest, TheDenoiseFlagRoundTrips) {
  // The unusual options above have the neighbours' prediction on, which excludes the denoising.
  PipelineOptions o = Unusual();
  o.prediction_enabled = false;
  o.uncertainty.judge_combination = false;
  o.denoise_enabled = true;
  o.frame_pair.two_returns_radius_px = 0;  // the pooled check excludes the denoising too
  const PipelineOptions back = ParsePipelineConfig(PipelineConfigToYaml(o), "denoised");
  ExpectSameOptions(o, back);
  EXPECT_TRUE(back.denoise_enabled);
}

TEST(PipelineConfigTest, PrintedDefaultsNameEveryStage) {
  const std::string text = PipelineConfigToYaml(PipelineOptions{});
  for (const char* key :
       {"metric_conversion:", "calibration:", "accuracy:", "filters:", "controller:",
        "point_cloud:", "false_color:", "stats:", "kind: may-incremental", "max_delta_l_m: 0.07",
        "exclude_flags: [invalid]", "loop_gain: 0.5", "frame_rate_hz: 0"}) {
    EXPECT_NE(text.find(key), std::string::npos) << key;
  }
}

TEST(PipelineConfigTest, MissingKeysKeepDefaults) {
  const PipelineOptions o = ParsePipelineConfig(
      "filters:\n  accuracy:\n    max_delta_l_m: 0.1\ncontroller:\n  kind: may-incremental\n",
      "partial");
  EXPECT_EQ(o.filters.accuracy.max_delta_l_m, 0.1);
  EXPECT_EQ(o.controller.kind, ControllerKind::kMayIncremental);
  EXPECT_EQ(o.controller.target_intensity, ControllerOptions{}.target_intensity);
  EXPECT_TRUE(o.filters.saturation_enabled);
  const PipelineOptions empty = ParsePipelineConfig("", "empty");
  EXPECT_TRUE(empty.accuracy_enabled);
}

// Expects Error(code) whose message contains every string of `parts`.
void ExpectError(const std::string& yaml, ErrorCode code,
                 std::initializer_list<const char*> parts) {
  try {
    (void)ParsePipelineConfig(yaml, "conf.yaml");
    FAIL() << "no error for:\n" << yaml;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    for (const char* p : parts) {
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos)
          << "'" << p << "' not in: " << e.what();
    }
  }
}

TEST(PipelineConfigTest, UnknownKeysNameFileLineAndKey) {
  ExpectError("filters:\n  accuracy:\n    max_delta_lm: 0.1\n", ErrorCode::kFormat,
              {"conf.yaml:3:", "filters.accuracy.max_delta_lm", "max_delta_l_m"});
  ExpectError("accuracy:\n  enabled: true\nfilterz: {}\n", ErrorCode::kFormat,
              {"conf.yaml:3:", "'filterz'"});
}

TEST(PipelineConfigTest, WrongTypesNameFileLineAndKey) {
  ExpectError("accuracy:\n  scale: big\n", ErrorCode::kFormat,
              {"conf.yaml:2:", "accuracy.scale", "a number", "'big'"});
  ExpectError("filters:\n  weingarten:\n    min_points: 2.5\n", ErrorCode::kFormat,
              {"conf.yaml:3:", "filters.weingarten.min_points", "an integer"});
  ExpectError("accuracy:\n  enabled: maybe\n", ErrorCode::kFormat,
              {"conf.yaml:2:", "accuracy.enabled", "true or false"});
  ExpectError("controller:\n  kind: pid\n", ErrorCode::kFormat,
              {"conf.yaml:2:", "controller.kind", "pid"});
  ExpectError("controller:\n  exclude_flags: [invalid, purple]\n", ErrorCode::kFormat,
              {"conf.yaml:2:", "controller.exclude_flags", "purple"});
  ExpectError("controller:\n  exclude_flags: invalid\n", ErrorCode::kFormat,
              {"conf.yaml:2:", "a list of flag names"});
  ExpectError("filters: 3\n", ErrorCode::kFormat, {"conf.yaml:1:", "'filters' must be a mapping"});
  ExpectError("- 1\n- 2\n", ErrorCode::kFormat, {"conf.yaml:1:", "must be a mapping"});
  ExpectError("filters: {accuracy: [\n", ErrorCode::kFormat, {"conf.yaml", "not YAML"});
  // Quoted scalars are strings, not numbers or booleans.
  ExpectError("filters:\n  range:\n    max_distance_m: \"5\"\n", ErrorCode::kFormat,
              {"conf.yaml:3:", "filters.range.max_distance_m", "a number"});
  ExpectError("filters:\n  weingarten:\n    min_points: '7'\n", ErrorCode::kFormat,
              {"conf.yaml:3:", "filters.weingarten.min_points", "an integer"});
  ExpectError("accuracy:\n  enabled: \"true\"\n", ErrorCode::kFormat,
              {"conf.yaml:2:", "accuracy.enabled", "true or false"});
}

TEST(PipelineConfigTest, ARepeatedKeyIsAnErrorNotASilentlyDroppedValue) {
  // yaml-cpp keeps both pairs and returns the first: the second value would be lost.
  ExpectError("denoise:\n  radius_px: 1\n  radius_px: 9\n", ErrorCode::kFormat,
              {"conf.yaml:3:", "'radius_px'", "twice"});
  ExpectError("controller:\n  kind: fixed\n  kind: bogus\n", ErrorCode::kFormat,
              {"conf.yaml:3:", "'kind'", "twice"});
  ExpectError("filters: {}\naccuracy: {}\nfilters: {}\n", ErrorCode::kFormat,
              {"conf.yaml:3:", "'filters'", "twice"});
  // The same key in two different mappings is fine, and so is an alias used twice.
  const PipelineOptions o = ParsePipelineConfig(
      "filters:\n  accuracy:\n    enabled: true\n  amplitude: &on\n    enabled: true\n"
      "  range: *on\naccuracy:\n  enabled: true\n",
      "conf.yaml");
  EXPECT_TRUE(o.filters.amplitude_enabled);
  EXPECT_TRUE(o.filters.range_enabled);
}

TEST(PipelineConfigTest, OutOfRangeValuesNameTheField) {
  ExpectError("filters:\n  accuracy:\n    max_delta_l_m: -1\n", ErrorCode::kInvalidArgument,
              {"conf.yaml", "filters.accuracy", "max_delta_l_m"});
  ExpectError("controller:\n  target_intensity: .nan\n", ErrorCode::kInvalidArgument,
              {"conf.yaml", "controller"});
  // The accuracy filter reads ΔL, so it cannot run with ΔL off.
  ExpectError("accuracy:\n  enabled: false\n", ErrorCode::kInvalidArgument,
              {"conf.yaml", "accuracy.enabled"});
}

class PipelineConfigFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("tofcam_pipeline_config_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(PipelineConfigFileTest, LoadsAFileAndResolvesTheCalibrationBesideIt) {
  const fs::path path = dir_ / "run.yaml";
  std::ofstream(path) << "calibration:\n  file: cal.yaml\n";
  const PipelineOptions o = LoadPipelineConfig(path);
  EXPECT_EQ(fs::path(o.calibration_file), dir_ / "cal.yaml");
  std::ofstream(path) << "calibration:\n  file: /abs/cal.yaml\n";
  EXPECT_EQ(LoadPipelineConfig(path).calibration_file, "/abs/cal.yaml");
}

TEST_F(PipelineConfigFileTest, MissingFileIsNotFound) {
  try {
    (void)LoadPipelineConfig(dir_ / "nope.yaml");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kNotFound);
    EXPECT_NE(std::string(e.what()).find("nope.yaml"), std::string::npos);
  }
}

TEST_F(PipelineConfigFileTest, MissingCalibrationFileIsNotFound) {
  PipelineOptions o;
  o.calibration_file = (dir_ / "missing-cal.yaml").string();
  EXPECT_THROW(LoadPipelineCalibration(o, CameraInfo{}), Error);
  try {
    LoadPipelineCalibration(o, CameraInfo{});
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kNotFound);
  }
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

OffsetCalibration Measured() {
  OffsetCalibration c;
  c.camera_model = "SR-2";
  c.width = 2;
  c.height = 2;
  c.offset_m = Image<float>(2, 2, 0.0f);
  c.noise = NoiseCalibration();
  c.noise->delta_l_scale = 0.25;
  c.noise->r_squared = 0.8;
  c.noise->frames = 30;
  c.noise->pixels_used = 4;
  ControllerSetpoint p;
  p.target_intensity = 25000.0;
  p.bias_register = 130;
  p.gain_register_per_intensity = 0.0025;
  p.scene = "sim:pavilion";
  c.controller_setpoint = p;
  return c;
}

TEST(MeasuredDefaultsTest, CalibrationThenSourceThenDefaultAndExplicitKeysWin) {
  // Nothing measured: the paper's scale 1 and the controller defaults stay.
  std::set<std::string> given;
  PipelineOptions plain = ParsePipelineConfig("", "empty", {}, &given);
  EXPECT_TRUE(given.empty());
  MeasuredDefaults from = ApplyMeasuredDefaults(plain, given);
  EXPECT_EQ(plain.accuracy.scale, 1.0);
  EXPECT_NE(from.delta_l_scale.find("default"), std::string::npos);
  EXPECT_EQ(plain.controller.target_intensity, 16000.0);

  // The source's figure when the calibration has none.
  from = ApplyMeasuredDefaults(plain, given, 0.0157, "the importer");
  EXPECT_EQ(plain.accuracy.scale, 0.0157);
  EXPECT_EQ(from.delta_l_scale, "the importer");

  // The calibration's measurements beat the source's.
  PipelineOptions o;
  o.calibration = Measured();
  from = ApplyMeasuredDefaults(o, given, 0.0157, "the importer");
  EXPECT_EQ(o.accuracy.scale, 0.25);
  EXPECT_NE(from.delta_l_scale.find("noise calibration"), std::string::npos);
  EXPECT_EQ(o.controller.target_intensity, 25000.0);
  EXPECT_EQ(o.controller.bias_register, 130);
  EXPECT_EQ(o.controller.gain_register_per_intensity, 0.0025);
  EXPECT_NE(from.controller.find("sim:pavilion"), std::string::npos);

  // A printed default configuration read back pins none of the measured values: they are
  // printed commented out while they hold the default.
  const std::string printed = PipelineConfigToYaml(PipelineOptions{});
  EXPECT_NE(printed.find("  # scale: 1.0"), std::string::npos) << printed;
  EXPECT_NE(printed.find("  # bias_register: 40"), std::string::npos) << printed;
  (void)ParsePipelineConfig(printed, "printed", {}, &given);
  for (const char* key : {"accuracy.scale", "controller.target_intensity",
                          "controller.gain_register_per_intensity", "controller.bias_register"}) {
    EXPECT_EQ(given.count(key), 0u) << key;
  }
  EXPECT_EQ(given.count("filters.accuracy.max_delta_l_m"), 1u);

  // A measured key the configuration set on purpose to its default stays pinned when printed
  // with the configuration's given keys.
  std::set<std::string> pinned_keys;
  const PipelineOptions pinned =
      ParsePipelineConfig("accuracy:\n  scale: 1.0\n", "conf", {}, &pinned_keys);
  const std::string pinned_text = PipelineConfigToYaml(pinned, &pinned_keys);
  EXPECT_NE(pinned_text.find("\n  scale: 1.0"), std::string::npos) << pinned_text;
  EXPECT_NE(pinned_text.find("  # bias_register: 40"), std::string::npos) << pinned_text;
  (void)ParsePipelineConfig(pinned_text, "printed", {}, &given);
  EXPECT_EQ(given.count("accuracy.scale"), 1u);

  // Keys the configuration gives are never replaced.
  PipelineOptions explicit_keys = ParsePipelineConfig(
      "accuracy:\n  scale: 0.5\ncontroller:\n  bias_register: 60\n", "conf", {}, &given);
  EXPECT_EQ(given, (std::set<std::string>{"accuracy", "accuracy.scale", "controller",
                                          "controller.bias_register"}));
  explicit_keys.calibration = Measured();
  from = ApplyMeasuredDefaults(explicit_keys, given, 0.0157, "the importer");
  EXPECT_EQ(explicit_keys.accuracy.scale, 0.5);
  EXPECT_NE(from.delta_l_scale.find("configuration"), std::string::npos);
  EXPECT_EQ(explicit_keys.controller.bias_register, 60);
  EXPECT_EQ(explicit_keys.controller.target_intensity, 25000.0);  // not given: measured

  // A set point measured on a camera with a longer register range (generic640x480: 1..2000)
  // widens the default bounds 1..255 instead of being clamped to them; bounds the configuration
  // gives still clamp it.
  PipelineOptions wide;
  wide.calibration = Measured();
  wide.calibration->controller_setpoint->bias_register = 986;
  (void)ApplyMeasuredDefaults(wide, {});
  EXPECT_EQ(wide.controller.bias_register, 986);
  EXPECT_EQ(wide.controller.max_register, 986);
  EXPECT_EQ(wide.controller.min_register, 1);
  PipelineOptions bounded =
      ParsePipelineConfig("controller:\n  max_register: 500\n", "conf", {}, &given);
  bounded.calibration = wide.calibration;
  (void)ApplyMeasuredDefaults(bounded, given);
  EXPECT_EQ(bounded.controller.bias_register, 500);
}

}  // namespace
}  // namespace tofcam

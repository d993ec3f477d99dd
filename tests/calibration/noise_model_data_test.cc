// The noise model against data nobody tuned it on: static sequences of the simulator's scenes
// and the real ifm O3D303 file (issue 14's targets: the fitted model ranks the measured
// temporal σ at least as well as eq. 2, within sampling noise, and predicts every decile of it
// within 25 %, on held-out pixels).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "tofcam/accuracy/noise_model.h"
#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/io/calibration_file.h"
#include "tofcam/io/importers.h"
#include "tofcam/io/pipeline_config.h"
#include "tofcam/pipeline/metric_conversion.h"
#include "tofcam/pipeline/pipeline.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam {
namespace {

// The standard error of Spearman's ρ over n pixels (Bonett & Wright 2000): two of them is the
// tie band the targets allow; beyond it a difference is not sampling noise.
double RhoStandardError(double rho, int n) {
  return (1 - rho * rho) * std::sqrt((1 + rho * rho / 2) / (n - 3.0));
}

void ExpectTargets(const NoiseModelFit& fit, const std::string& what) {
  SCOPED_TRACE(what + ": model " + fit.features);
  const double se = RhoStandardError(fit.eq2.spearman, fit.held_out_pixels);
  EXPECT_GE(fit.fitted.spearman, fit.eq2.spearman - 2 * se);
  EXPECT_LE(fit.fitted.max_decile_error, 0.25);
  std::printf("%s: rho model %.3f eq2 %.3f (se %.3f), worst decile model %.0f %% eq2 %.0f %%\n",
              what.c_str(), fit.fitted.spearman, fit.eq2.spearman, se,
              100 * fit.fitted.max_decile_error, 100 * fit.eq2.max_decile_error);
}

// `count` frames of the scene's view at t = 0, held still (dynamic scenes frozen), so the
// temporal σ is noise only, at the exposure the default controller settles at (as a user runs
// `tofcam calibrate --noise` at the camera's working exposure).
std::vector<MetricFrame> SimFrames(const std::string& scene, int count) {
  sim::SimulatorOptions o;
  o.seed = 11;
  sim::SimulatedCamera camera(sim::StaticView(sim::LoadBuiltinScene(scene, {})),
                              sim::ResolveCameraModel("sr2"), o);
  PipelineOptions po;
  po.cloud_enabled = false;
  Pipeline settle(po, camera.Info());
  camera.SetIntegrationTimeRegister(settle.InitialIntegrationRegister());
  for (int k = 0; k < 30; ++k) {
    camera.SetIntegrationTimeRegister(settle.Process(*camera.Grab()).next_integration_register);
  }
  std::vector<MetricFrame> frames;
  for (int k = 0; k < count; ++k) frames.push_back(ConvertToMetric(*camera.Grab()));
  return frames;
}

TEST(NoiseModelData, SimulatedScenes) {
  // Not a reproduction of anything: the simulator's noise is eq. 2's physics, so the check is
  // that the fitted model loses nothing against it where eq. 2 holds by construction.
  // The hand at this exposure clips its fingers (they bloom into their neighbours): the clipped
  // pixels are left out of the fit as the saturation filter rejects them; before they were
  // (the SR-2 has no saturation bit), this scene missed the decile target by 57 %.
  for (const std::string& scene : sim::BuiltinSceneNames()) {
    ExpectTargets(FitNoiseModel(SimFrames(scene, 16)), "sim:" + scene);
  }
}

TEST(NoiseModelData, RealIfmO3d303) {
  // Only 3 frames exist (σ per pixel scatters ~50 %), hence min_frames 3. Eq. 2's scale fitted
  // on the same file misses the deciles by ~90 % (its slope in amplitude is wrong for this
  // camera's normalised amplitude); the model must not.
  const ImportedSequence seq = ImportIfmO3d3xx(std::filesystem::path(TOFCAM_TEST_DATA_DIR) /
                                               "real" / "ifm_o3d303" / "o3d3xx.h5");
  std::vector<MetricFrame> frames;
  for (const Frame& f : seq.frames) frames.push_back(ConvertToMetric(f));
  NoiseModelFitOptions options;
  options.min_frames = 3;
  const NoiseModelFit fit = FitNoiseModel(frames, options);
  ExpectTargets(fit, "ifm O3D303");
  EXPECT_GT(fit.eq2.max_decile_error, 0.25);  // what the model fixes
}

TEST(NoiseModelData, CalibrateStoresTheModelAndThePipelineUsesIt) {
  sim::SimulatorOptions o;
  o.seed = 3;
  sim::SimulatedCamera camera(sim::LoadBuiltinScene("lamps", {}), sim::ResolveCameraModel("sr2"),
                              o);
  NoiseCalibrationOptions options;
  options.frames = 12;
  NoiseModelReport report;
  OffsetCalibration calibration;
  calibration.camera_model = camera.Info().model;
  calibration.width = camera.Info().width();
  calibration.height = camera.Info().height();
  calibration.modulation_frequency_hz = camera.Info().modulation_frequency_hz;
  calibration.offset_m = Image<float>(calibration.width, calibration.height, 0.0f);
  calibration.noise = CalibrateNoise(camera, options, {}, nullptr, &report);
  ASSERT_TRUE(report.fit.has_value()) << report.note;
  ASSERT_TRUE(report.stored) << report.note;
  ASSERT_TRUE(calibration.noise->model.has_value());

  // The file keeps the model's doubles bit-exactly (written with 17 significant digits).
  const std::filesystem::path file = std::filesystem::temp_directory_path() /
                                     ("tofcam_noise_model_" + std::to_string(::getpid()) + ".yaml");
  SaveCalibration(file, calibration);
  const OffsetCalibration loaded = LoadCalibration(file);
  std::filesystem::remove(file);
  ASSERT_TRUE(loaded.noise && loaded.noise->model);
  const NoiseModel& a = *calibration.noise->model;
  const NoiseModel& b = *loaded.noise->model;
  EXPECT_EQ(a.intercept, b.intercept);
  EXPECT_EQ(a.log_amplitude, b.log_amplitude);
  EXPECT_EQ(a.amplitude_fraction, b.amplitude_fraction);
  EXPECT_EQ(a.amplitude_ref, b.amplitude_ref);
  EXPECT_EQ(a.log_edge, b.log_edge);
  EXPECT_EQ(a.edge_ref_m, b.edge_ref_m);
  // Measured: on the lamps the selection takes the edge channel (held out ρ 0.873 against 0.868
  // without), so the comparison below also covers the pipeline's neighbourhood edge term.
  EXPECT_NE(b.log_edge, 0.0);

  // Loaded into a pipeline, the ΔL stage outputs the model's σ (unless accuracy.scale is set).
  PipelineOptions p;
  p.calibration = loaded;
  (void)ApplyMeasuredDefaults(p, {}, std::nullopt, "");
  ASSERT_TRUE(p.accuracy.model.has_value());
  PipelineOptions q;
  q.calibration = loaded;
  (void)ApplyMeasuredDefaults(q, {"accuracy.scale"}, std::nullopt, "");
  EXPECT_FALSE(q.accuracy.model.has_value());
  Pipeline pipeline(p, camera.Info());
  const PipelineResult r = pipeline.Process(*camera.Grab());
  const MetricFrame& m = r.frame;
  // The edge channel (the lamps' model uses it) from the camera's own flags, as the pipeline.
  Image<float> edge;
  LocalDepthVariation(m.radial_distance_m, r.input_flags, edge);
  for (std::size_t i = 0; i < m.delta_l_m.size(); i += 211) {
    const double expected =
        PredictSigmaM(b, m.amplitude[i], m.intensity[i], m.radial_distance_m[i], 0.0, edge[i]);
    EXPECT_NEAR(m.delta_l_m[i], expected, 1e-5 * expected + 1e-9) << i;
  }
}

}  // namespace
}  // namespace tofcam

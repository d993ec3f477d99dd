// `tofcam demo`: the paper's system end to end on the simulated SR-2 (docs/demo.md).
//  1. per-pixel calibration against a simulated white wall (cached in <out>/calibration.yaml);
//  2. ~10 s at 30 frames/s of the `demo` scene (pavilion; a hand enters, lamps switch on, both
//     leave) through the pipeline with the paper's P-controller and accuracy filter;
//  3. a 180° pan sweep assembled into a panorama cloud and a false-colour strip.
// Everything lands in <out>/; the key numbers and where to look go to stdout.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/io/calibration_file.h"
#include "tofcam/io/cloud_io.h"
#include "tofcam/io/png.h"
#include "tofcam/pan/pan_view.h"
#include "tofcam/pipeline/pipeline.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::cli {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct DemoOptions {
  std::string out = "out/demo";
  std::uint64_t seed = 1;
  int frames = 300;
  int threads = 2;
  bool recalibrate = false;
  double wall_distance_m = 2.0;
};

// A moment of the demo scene worth a picture (scenes/demo.yaml: the hand is in place 2.5-4.5 s,
// the lamps are on 6-8.5 s).
struct Moment {
  const char* name;
  const char* what;
  double time_s;
};
constexpr Moment kMoments[] = {
    {"before", "the pavilion before the hand", 1.0},
    {"hand", "a hand 0.22 m in front of the lens", 3.5},
    {"lamps", "two lamps switched on", 7.0},
};

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

nlohmann::json Real(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

std::string Mm(double value_m) {
  if (!std::isfinite(value_m)) return "-";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1f mm", value_m * 1e3);
  return buffer;
}

sim::SimulatorOptions Simulator(const DemoOptions& o, std::uint64_t seed_offset) {
  sim::SimulatorOptions s;
  s.seed = o.seed + seed_offset;
  s.threads = o.threads;
  return s;
}

// Step 1: the calibration file, reused when it fits the camera.
OffsetCalibration Calibrate(const DemoOptions& o, const sim::CameraModel& model,
                            const fs::path& path, nlohmann::json& report) {
  const CameraInfo info = model.Info(model.modulation_frequencies_hz.front());
  if (!o.recalibrate && fs::exists(path)) {
    try {
      OffsetCalibration cached = LoadCalibration(path);
      CheckCalibrationMatches(cached, info);
      std::printf(
          "1/3 calibration: reusing %s (%s, %dx%d, wall at %.2f m; --recalibrate to "
          "redo)\n",
          path.c_str(), cached.camera_model.c_str(), cached.width, cached.height,
          cached.wall_distance_m);
      report["reused"] = true;
      return cached;
    } catch (const Error& e) {
      std::printf("1/3 calibration: %s does not fit (%s); calibrating again\n", path.c_str(),
                  e.what());
    }
  }
  const Clock::time_point start = Clock::now();
  std::printf("1/3 calibration: simulated white wall at %.2f m (paper section II-B)...\n",
              o.wall_distance_m);
  std::fflush(stdout);
  sim::SimulatedCamera wall(
      sim::LoadBuiltinScene("wall", {{"distance_m", std::to_string(o.wall_distance_m)}}), model,
      Simulator(o, 1000));
  WallCalibrationOptions options;
  options.wall_distance_m = o.wall_distance_m;
  WallCalibrationReport r;
  OffsetCalibration calibration = CalibrateOffsets(wall, options, {}, &r);
  calibration.created_unix_s = std::chrono::duration_cast<std::chrono::seconds>(
                                   std::chrono::system_clock::now().time_since_epoch())
                                   .count();
  SaveCalibration(path, calibration);
  std::printf(
      "    register %d after %d exposure frames, %d warm-up frames (drift %.3f mm/s), "
      "%d frames averaged\n",
      r.integration_register, r.exposure_frames, r.warmup_frames, r.drift_m_per_s * 1e3,
      options.frames);
  std::printf(
      "    offsets: mean %.1f mm, RMS %.1f mm (the error eq. 1 removes); per-frame noise "
      "%.1f mm; %.1f s\n",
      r.mean_offset_m * 1e3, r.offset_rms_m * 1e3, r.noise_sigma_m * 1e3, Seconds(start));
  report["reused"] = false;
  report["integration_register"] = r.integration_register;
  report["warmup_frames"] = r.warmup_frames;
  report["offset_rms_m"] = r.offset_rms_m;
  report["noise_sigma_m"] = r.noise_sigma_m;
  report["seconds"] = Seconds(start);
  return calibration;
}

// The noise calibration of stage 3: temporal σ of static wall frames against ΔL of eq. 2 gives
// the factor that turns ΔL into metres of standard deviation (tof-notes §1, note on eq. 2).
double FitNoiseScale(const DemoOptions& o, const sim::CameraModel& model,
                     const OffsetCalibration& calibration, nlohmann::json& report) {
  constexpr int kFrames = 30;
  sim::SimulatedCamera wall(
      sim::LoadBuiltinScene("wall", {{"distance_m", std::to_string(calibration.wall_distance_m)}}),
      model, Simulator(o, 2000));
  wall.SetIntegrationTimeRegister(calibration.integration_time_register);
  std::vector<MetricFrame> frames;
  for (int k = 0; k < kFrames; ++k) {
    const std::optional<Frame> frame = wall.Grab();
    if (!frame) throw Error(ErrorCode::kInternal, "the simulator stopped delivering frames");
    frames.push_back(ConvertToMetric(*frame));
  }
  const DeltaLScaleFit fit = FitDeltaLScale(frames);
  std::printf(
      "    noise calibration: sigma = %.3f x dL of eq. 2 (R^2 %.3f, %d pixels, %d frames); "
      "dL below is eq. 2 times this\n",
      fit.scale, fit.r_squared, fit.pixels_used, fit.frames);
  report["delta_l_scale"] = fit.scale;
  report["delta_l_scale_r_squared"] = fit.r_squared;
  return fit.scale;
}

// Tunes the printed P-law for the scene (the paper gives I_A but no V_p or c_0): MayIncremental,
// which has no steady-state offset (its gain set from a first slope measurement so that it
// converges), finds the register c* at which the empty hall gives I_A;
// c_0 = c* then removes the position form's offset there (tof-notes §1). The slope k of
// intensity over register at c* sets V_p = 0.4 / k: the loop gain V_p k stays below 1 (no
// oscillation) even where the scene is twice as responsive, as with the hand close to the lens.
ControllerOptions TuneController(const DemoOptions& o, const sim::CameraModel& model,
                                 nlohmann::json& report) {
  constexpr int kProbeFrames = 40;
  sim::SimulatedCamera probe(sim::LoadBuiltinScene("demo"), model, Simulator(o, 3000));
  PipelineOptions probe_options;
  probe_options.controller_enabled = false;  // the search below drives the register
  Pipeline pipeline(probe_options, probe.Info());
  PipelineResult result;
  const auto grab = [&] {
    const std::optional<Frame> frame = probe.Grab();
    if (!frame) throw Error(ErrorCode::kInternal, "the simulator stopped delivering frames");
    pipeline.Process(*frame, result);
  };
  // Mean intensity per register step between registers `at` - 5 and `at` + 5.
  const auto slope_at = [&](int at) {
    const int lo = std::max(at - 5, model.min_integration_register);
    const int hi = std::min(at + 5, model.max_integration_register);
    probe.SetIntegrationTimeRegister(lo);
    grab();
    const double low = result.stats.mean_intensity;
    probe.SetIntegrationTimeRegister(hi);
    grab();
    return (result.stats.mean_intensity - low) / std::max(hi - lo, 1);
  };

  ControllerOptions c;
  c.target_intensity = 16000.0;  // the paper's I_A (15000..18000 worked)
  const double first_slope = slope_at(c.bias_register);
  c.kind = ControllerKind::kMayIncremental;
  c.gain_register_per_intensity = first_slope > 0 ? std::min(0.5 / first_slope, 1.0) : 2.5e-4;
  const std::unique_ptr<IntegrationTimeController> search = MakeController(c);
  probe.SetIntegrationTimeRegister(c.bias_register);
  for (int k = 0; k < kProbeFrames; ++k) {
    grab();
    probe.SetIntegrationTimeRegister(search->Update(result.frame));
  }
  const int settled = probe.IntegrationTimeRegister();
  const double slope = slope_at(settled);

  c.kind = ControllerKind::kMayProportional;
  c.bias_register = settled;
  c.gain_register_per_intensity = slope > 0 ? std::min(0.4 / slope, 1.0) : 2.5e-4;
  std::printf(
      "    P-controller: empty hall reaches I_A = %.0f at register %d, %.0f intensity "
      "units per register -> c_0 = %d, V_p = %.3g\n",
      c.target_intensity, settled, slope, c.bias_register, c.gain_register_per_intensity);
  report["target_intensity"] = c.target_intensity;
  report["bias_register"] = c.bias_register;
  report["gain_register_per_intensity"] = c.gain_register_per_intensity;
  report["intensity_per_register"] = slope;
  return c;
}

// Statistics of the raw view: the same frame judged with the input flags only.
FrameStats RawStats(const PipelineResult& result, const PipelineOptions& options) {
  MetricFrame raw = result.frame;
  raw.flags = result.input_flags;
  FrameStatsOptions stats = options.stats;
  stats.intensity_roi = options.controller.roi;
  stats.intensity_exclude_flags = options.controller.exclude_flags;
  return ComputeFrameStats(raw, stats);
}

nlohmann::json StatsJson(const FrameStats& s) {
  return {{"sequence", s.sequence},
          {"timestamp_s", s.timestamp_s},
          {"integration_register", s.integration_time_register},
          {"mean_intensity", Real(s.mean_intensity)},
          {"valid_fraction", Real(s.valid_fraction)},
          {"mean_delta_l_m", Real(s.mean_delta_l_m)},
          {"rmse_m", Real(s.rmse_m)},
          {"bad_removed_fraction", Real(s.bad_removed_fraction)},
          {"good_kept_fraction", Real(s.good_kept_fraction)}};
}

void RunDemo(const DemoOptions& o) {
  if (o.frames < 1 || o.frames > 100000) {
    throw Error(ErrorCode::kInvalidArgument,
                "--frames " + std::to_string(o.frames) + " must be in [1, 100000]");
  }
  if (o.threads < 1 || o.threads > 64) {
    throw Error(ErrorCode::kInvalidArgument,
                "--threads " + std::to_string(o.threads) + " must be in [1, 64]");
  }
  const Clock::time_point start = Clock::now();
  const fs::path out(o.out);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) {
    throw Error(ErrorCode::kIo, "--out " + o.out + ": cannot create the directory" +
                                    (ec ? ": " + ec.message() : std::string()));
  }
  nlohmann::json summary;
  const sim::CameraModel model = sim::ResolveCameraModel("sr2");

  // --- 1. Calibration -------------------------------------------------------------------------
  OffsetCalibration calibration =
      Calibrate(o, model, out / "calibration.yaml", summary["calibration"]);
  const double delta_l_scale = FitNoiseScale(o, model, calibration, summary["calibration"]);
  const ControllerOptions controller = TuneController(o, model, summary["controller"]);

  // --- 2. The demo sequence -------------------------------------------------------------------
  const Clock::time_point run_start = Clock::now();
  sim::SimulatedCamera camera(sim::LoadBuiltinScene("demo"), model, Simulator(o, 0));
  PipelineOptions options;
  options.calibration = std::move(calibration);
  options.controller = controller;
  options.filters.accuracy_enabled = true;
  // ΔL in metres of standard deviation (the noise calibration's scale on eq. 2), so the paper's
  // "fixed threshold" keeps its meaning whatever the register gain of the camera.
  options.accuracy.scale = delta_l_scale;
  Pipeline pipeline(options, camera.Info());
  camera.SetIntegrationTimeRegister(pipeline.InitialIntegrationRegister());
  const ControllerOptions& c = pipeline.options().controller;
  std::printf(
      "2/3 run: %d frames of the 'demo' scene (%.0f s at %.0f frames/s), controller %s "
      "(I_A %.0f, V_p %.2g, c_0 %d), accuracy filter dL <= %.0f mm\n",
      o.frames, o.frames / camera.Info().max_frame_rate_hz, camera.Info().max_frame_rate_hz,
      std::string(pipeline.ControllerName()).c_str(), c.target_intensity,
      c.gain_register_per_intensity, c.bias_register, options.filters.accuracy.max_delta_l_m * 1e3);
  std::fflush(stdout);

  const fs::path csv_path = out / "frames.csv";
  std::string csv = "frame," + FrameStatsCsvHeader() + "\n";
  RunStatsAccumulator accumulator;
  PipelineResult result;
  std::size_t next_moment = 0;
  nlohmann::json moments = nlohmann::json::array();
  Clock::time_point last_status = run_start;
  for (int k = 0; k < o.frames; ++k) {
    const std::optional<Frame> frame = camera.Grab();
    if (!frame) throw Error(ErrorCode::kInternal, "the simulator stopped delivering frames");
    pipeline.Process(*frame, result);
    camera.SetIntegrationTimeRegister(result.next_integration_register);
    accumulator.Add(result.stats);
    csv += std::to_string(k) + "," + FrameStatsCsvRow(result.stats) + "\n";

    if (next_moment < std::size(kMoments) &&
        result.stats.timestamp_s >= kMoments[next_moment].time_s) {
      const Moment& m = kMoments[next_moment++];
      const std::string stem = std::string("moment_") + m.name;
      WritePngRgb8(out / (stem + "_raw.png"), pipeline.RenderRaw(result));
      WritePngRgb8(out / (stem + "_filtered.png"), pipeline.RenderFiltered(result));
      WritePly(out / (stem + ".ply"), result.cloud, PlyFormat::kBinary, /*only_valid=*/true);
      const FrameStats raw = RawStats(result, pipeline.options());
      const FrameStats& s = result.stats;
      std::printf(
          "    t=%.2f s %-36s register %3d, intensity %5.0f | raw: valid %5.1f%%, RMSE "
          "%s | filtered: valid %5.1f%%, RMSE %s, bad removed %.0f%%, good kept %.0f%%\n",
          s.timestamp_s, m.what, s.integration_time_register, s.mean_intensity,
          raw.valid_fraction * 100, Mm(raw.rmse_m).c_str(), s.valid_fraction * 100,
          Mm(s.rmse_m).c_str(), s.bad_removed_fraction * 100, s.good_kept_fraction * 100);
      moments.push_back({{"name", m.name},
                         {"what", m.what},
                         {"raw", StatsJson(raw)},
                         {"filtered", StatsJson(s)},
                         {"files", {stem + "_raw.png", stem + "_filtered.png", stem + ".ply"}}});
    }
    if (Seconds(last_status) >= 1.0) {
      std::fprintf(stderr, "demo: frame %d/%d  t=%.1f s  register %d  valid %.1f%%\n", k + 1,
                   o.frames, result.stats.timestamp_s, result.stats.integration_time_register,
                   result.stats.valid_fraction * 100);
      last_status = Clock::now();
    }
  }
  WriteFileAtomically(csv_path, csv);
  const RunSummary run = accumulator.Summary();
  const double run_s = Seconds(run_start);
  std::printf(
      "    %llu frames in %.1f s (%.1f frames/s incl. simulation): mean valid %.1f%%, "
      "mean dL %s, RMSE of kept pixels %s, bad pixels removed %.1f%%, good kept %.1f%%\n",
      static_cast<unsigned long long>(run.frames), run_s, run.frames / run_s,
      run.mean_valid_fraction * 100, Mm(run.mean_delta_l_m).c_str(), Mm(run.rmse_m).c_str(),
      run.bad_removed_fraction * 100, run.good_kept_fraction * 100);

  // --- 3. Pan sweep ---------------------------------------------------------------------------
  const Clock::time_point pan_start = Clock::now();
  const std::vector<double> angles_deg = {75, 45, 15, -15, -45, -75};
  constexpr int kSettleFrames = 4;  // the controller follows each new view for a few frames
  std::printf("3/3 pan sweep: %zu angles from %+.0f to %+.0f deg, %d frames each\n",
              angles_deg.size(), angles_deg.front(), angles_deg.back(), kSettleFrames);
  std::fflush(stdout);
  std::vector<MetricFrame> views, raw_views;
  for (const double angle_deg : angles_deg) {
    camera.SetPanAngleRad(angle_deg * kPi / 180.0);
    for (int k = 0; k < kSettleFrames; ++k) {
      const std::optional<Frame> frame = camera.Grab();
      if (!frame) throw Error(ErrorCode::kInternal, "the simulator stopped delivering frames");
      pipeline.Process(*frame, result);
      camera.SetIntegrationTimeRegister(result.next_integration_register);
    }
    views.push_back(result.frame);
    raw_views.push_back(result.frame);
    raw_views.back().flags = result.input_flags;
  }
  // Two views of the same frames: "raw" with the flags before the filters (only pixels without
  // a measurement dropped), "filtered" without everything the pipeline rejected.
  PanViewOptions pan;
  pan.pan_unit = camera.scene().pan_unit;
  pan.color = options.color;
  const double far_m = options.color.far_m > 0
                           ? options.color.far_m
                           : UnambiguousRangeM(camera.Info().modulation_frequency_hz);
  nlohmann::json pan_report = {{"angles_deg", angles_deg}};
  for (const bool filtered : {false, true}) {
    const PanView view = MakePanView(filtered ? views : raw_views, pipeline.rays(), pan);
    const std::string stem = filtered ? "panorama_filtered" : "panorama_raw";
    WritePly(out / (stem + ".ply"), view.cloud);
    WritePngRgb8(out / (stem + ".png"), AddLegend(view.panorama, options.color.near_m, far_m));
    std::printf("    %-8s %6zu points in the 180 deg cloud, panorama %dx%d px at %.1f deg/px\n",
                filtered ? "filtered" : "raw", view.cloud.size(), view.panorama.width(),
                view.panorama.height(), pan.resolution_deg);
    pan_report[filtered ? "filtered_points" : "raw_points"] = view.cloud.size();
    pan_report["panorama_width_px"] = view.panorama.width();
    pan_report["panorama_height_px"] = view.panorama.height();
  }
  std::printf("    %.1f s\n", Seconds(pan_start));

  summary["frames"] = run.frames;
  summary["scene"] = "demo";
  summary["camera_model"] = camera.Info().model;
  summary["controller"]["kind"] = std::string(pipeline.ControllerName());
  summary["max_delta_l_m"] = options.filters.accuracy.max_delta_l_m;
  summary["mean_valid_fraction"] = Real(run.mean_valid_fraction);
  summary["mean_delta_l_m"] = Real(run.mean_delta_l_m);
  summary["rmse_m"] = Real(run.rmse_m);
  summary["bad_removed_fraction"] = Real(run.bad_removed_fraction);
  summary["good_kept_fraction"] = Real(run.good_kept_fraction);
  summary["bad_error_m"] = options.stats.bad_error_m;
  summary["mean_frames_per_s"] = Real(run.frames / run_s);
  summary["moments"] = moments;
  summary["pan"] = pan_report;
  summary["elapsed_s"] = Seconds(start);
  WriteFileAtomically(out / "summary.json", summary.dump(2) + "\n");

  std::printf("\ndone in %.1f s. Look at %s/:\n", Seconds(start), o.out.c_str());
  std::printf(
      "  moment_{before,hand,lamps}_{raw,filtered}.png  false colour (yellow near, blue "
      "far, black rejected) without / with the accuracy filter\n");
  std::printf("  moment_*.ply     the kept points of those frames (camera frame)\n");
  std::printf(
      "  panorama_{raw,filtered}.png  the 180 deg false-colour strip; .ply: its cloud "
      "(base frame of the pan unit)\n");
  std::printf("  frames.csv       one row per frame (register, intensity, valid, dL, RMSE)\n");
  std::printf("  summary.json     the numbers above; calibration.yaml the offset matrix\n");
}

void SetupDemoCommand(CLI::App& app) {
  auto o = std::make_shared<DemoOptions>();
  CLI::App* sub = app.add_subcommand(
      "demo", "The paper's system on the simulated SR-2: calibrate, run, pan (make demo)");
  sub->add_option("--out", o->out, "Output directory")->capture_default_str();
  sub->add_option("--seed", o->seed, "Simulator noise seed")->capture_default_str();
  sub->add_option("--frames", o->frames, "Frames of the demo sequence")->capture_default_str();
  sub->add_option("--threads", o->threads, "Simulator worker threads")->capture_default_str();
  sub->add_flag("--recalibrate", o->recalibrate, "Calibrate even when a cached file fits");
  sub->callback([o] { RunDemo(*o); });
}

TOFCAM_REGISTER_COMMAND("demo", SetupDemoCommand);

}  // namespace
}  // namespace tofcam::cli

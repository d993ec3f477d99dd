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
#include <limits>
#include <map>
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
  int frames = 0;           // 0: as many as the scene's duration takes
  double duration_s = 0.0;  // camera time to run; 0: the demo scene's duration (10 s)
  int threads = 2;
  bool recalibrate = false;
  double wall_distance_m = 2.0;
};

// The hall of the demo scene without the hand and the lamps: scenes/demo.yaml places its poster at
// 1.4 m and has 0.5 W/m² of daylight (keep the two in step). The controller's set point comes
// from an integration-time sweep of it, as the paper chose I_A from a sweep of its scene.
constexpr const char* kDemoHall = "pavilion?poster_distance_m=1.4&daylight_w_m2=0.5";

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

// Step 1: the calibration file (offsets, exposure offset, noise scale, controller set point),
// reused when it fits the camera; parts it lacks are measured and added.
OffsetCalibration Calibrate(const DemoOptions& o, const sim::CameraModel& model,
                            const fs::path& path, nlohmann::json& report) {
  const CameraInfo info = model.Info(model.modulation_frequencies_hz.front());
  // The demo runs at the camera's full rate (SR-2: 30 frames/s): every exposure it uses,
  // calibration included, leaves that rate.
  const int rate_register = MaxRegisterForFrameRate(info, info.max_frame_rate_hz);
  std::optional<OffsetCalibration> calibration;
  if (!o.recalibrate && fs::exists(path)) {
    try {
      OffsetCalibration cached = LoadCalibration(path);
      CheckCalibrationMatches(cached, info);
      std::printf(
          "1/3 calibration: reusing %s (%s, %dx%d, wall at %.2f m; --recalibrate to "
          "redo)\n",
          path.c_str(), cached.camera_model.c_str(), cached.width, cached.height,
          cached.wall_distance_m);
      if (cached.controller_setpoint && cached.controller_setpoint->bias_register > rate_register) {
        std::printf(
            "    its controller set point (c_0 %d) is beyond %.0f frames/s: measuring again\n",
            cached.controller_setpoint->bias_register, info.max_frame_rate_hz);
        cached.controller_setpoint.reset();
      }
      calibration = std::move(cached);
      report["reused"] = true;
    } catch (const Error& e) {
      std::printf("1/3 calibration: %s does not fit (%s); calibrating again\n", path.c_str(),
                  e.what());
    }
  }
  const Clock::time_point start = Clock::now();
  const std::map<std::string, std::string> wall_at = {
      {"distance_m", std::to_string(o.wall_distance_m)}};
  if (!calibration) {
    // A stated exposure (paper: "an optimal adjusted integration time"): the longest one that
    // keeps the frame rate, i.e. the best signal the demo's camera can have. The wall at 2 m is
    // darker than the paper's I_A even there, so an auto-exposure would only pin at a bound.
    std::printf(
        "1/3 calibration: simulated white wall at %.2f m (paper section II-B) at register %d "
        "(%.1f ms, the longest exposure at %.0f frames/s), then the exposure offset at 1/4 and "
        "1/2 of it...\n",
        o.wall_distance_m, rate_register, info.IntegrationTimeUs(rate_register) * 1e-3,
        info.max_frame_rate_hz);
    std::fflush(stdout);
    sim::SimulatedCamera wall(sim::LoadBuiltinScene("wall", wall_at), model, Simulator(o, 1000));
    WallCalibrationOptions options;
    options.wall_distance_m = o.wall_distance_m;
    options.controller.kind = ControllerKind::kFixed;
    options.controller.bias_register = rate_register;
    wall.SetIntegrationTimeRegister(rate_register);
    WallCalibrationReport r;
    calibration = CalibrateOffsets(wall, options, {}, &r);
    std::printf(
        "    register %d after %d exposure frames, %d warm-up frames (drift %.3f mm/s), "
        "%d frames averaged\n",
        r.integration_register, r.exposure_frames, r.warmup_frames, r.drift_m_per_s * 1e3,
        options.frames);
    std::printf(
        "    offsets: mean %.1f mm, RMS %.1f mm (the error eq. 1 removes); per-frame noise "
        "%.1f mm\n",
        r.mean_offset_m * 1e3, r.offset_rms_m * 1e3, r.noise_sigma_m * 1e3);
    std::printf(
        "    exposure offset: %.3f mm per ms of integration time (%zu registers; eq. 1 "
        "subtracts s (t - t_cal) per frame)\n",
        calibration->exposure_offset_m_per_ms * 1e3, r.exposure_registers.size());
    report["reused"] = false;
    report["integration_register"] = r.integration_register;
    report["warmup_frames"] = r.warmup_frames;
    report["offset_rms_m"] = r.offset_rms_m;
    report["noise_sigma_m"] = r.noise_sigma_m;
    report["exposure_offset_m_per_ms"] = calibration->exposure_offset_m_per_ms;
  }
  bool changed = !report.value("reused", false);
  if (!calibration->distance_correction) {
    // The wiggling error (odd harmonics, period L/4) is distance dependent: the offsets alone
    // leave w(t) - w(t_wall), tens of mm across the hall. The wall sweep (docs/calibration.md)
    // removes it; exposure-compensated, so it holds at every integration time.
    std::printf("    wall sweep 0.5..7 m for the distance-dependent correction...\n");
    std::fflush(stdout);
    std::unique_ptr<sim::SimulatedCamera> moved;
    std::uint64_t sweep_seed = 4000;
    const WallCameraSource source = [&](double distance_m) -> Camera& {
      moved.reset();
      moved = std::make_unique<sim::SimulatedCamera>(
          sim::LoadBuiltinScene("wall", {{"distance_m", std::to_string(distance_m)}}), model,
          Simulator(o, sweep_seed++));
      return *moved;
    };
    SweepOptions sweep;
    sweep.wall.wall_distance_m = calibration->wall_distance_m;
    SweepReport r;
    calibration = CalibrateDistanceCorrection(*calibration, source, sweep, {}, &r);
    std::printf(
        "    held-out walls: RMS error %.1f mm with the offsets only (eq. 1), %.1f mm with the "
        "distance correction (noise floor of the averages %.1f mm)\n",
        r.held_out_rms_before_m * 1e3, r.held_out_rms_after_m * 1e3,
        r.held_out_noise_floor_m * 1e3);
    report["sweep_held_out_rms_before_m"] = r.held_out_rms_before_m;
    report["sweep_held_out_rms_after_m"] = r.held_out_rms_after_m;
    report["sweep_held_out_noise_floor_m"] = r.held_out_noise_floor_m;
    changed = true;
  }
  if (!calibration->noise) {
    // Stage 3's noise calibration: temporal σ of static wall frames against ΔL of eq. 2 gives
    // the factor that turns ΔL into metres of standard deviation (tof-notes §1).
    sim::SimulatedCamera wall(sim::LoadBuiltinScene("wall", wall_at), model, Simulator(o, 2000));
    wall.SetIntegrationTimeRegister(calibration->integration_time_register);
    calibration->noise = CalibrateNoise(wall);
    changed = true;
  }
  std::printf(
      "    noise calibration: sigma = %.3f x dL of eq. 2 (R^2 %.2f, %d pixels, %d frames); "
      "dL below is eq. 2 times this\n",
      calibration->noise->delta_l_scale, calibration->noise->r_squared,
      calibration->noise->pixels_used, calibration->noise->frames);
  if (!calibration->controller_setpoint) {
    // The paper chose I_A from an integration-time sweep of its scene (fig. 3): a little below
    // the intensity at the amplitude maximum. Same here, on the hall of the demo scene.
    const auto [hall_name, hall_overrides] = sim::ParseSceneSpec(kDemoHall);
    sim::SimulatedCamera hall(sim::LoadBuiltinScene(hall_name, hall_overrides), model,
                              Simulator(o, 3000));
    IntegrationSweepOptions sweep_options;
    sweep_options.to_register = rate_register;  // exposures that keep the frame rate
    std::vector<IntegrationSweepPoint> sweep = SweepIntegrationTime(hall, sweep_options);
    ControllerSetpoint setpoint = ChooseSetpoint(sweep);
    setpoint.scene = std::string("sim:") + kDemoHall;
    calibration->controller_setpoint = setpoint;
    nlohmann::json points = nlohmann::json::array();
    for (const IntegrationSweepPoint& p : sweep) {
      points.push_back(
          {p.integration_register, p.mean_intensity, p.mean_amplitude, p.saturated_fraction});
    }
    report["integration_sweep"] = {
        {"columns", {"register", "intensity", "amplitude", "saturated_fraction"}},
        {"points", points}};
    changed = true;
  }
  const ControllerSetpoint& sp = *calibration->controller_setpoint;
  std::printf(
      "    controller set point (integration-time sweep of the empty hall, paper fig. 3): "
      "amplitude maximum at register %d, mean intensity %.0f there -> I_A = %.0f at c_0 = %d "
      "(%.0f intensity units per register), V_p = %.3g\n",
      sp.amplitude_max_register, sp.amplitude_max_intensity, sp.target_intensity, sp.bias_register,
      sp.intensity_per_register, sp.gain_register_per_intensity);
  if (changed) {
    calibration->created_unix_s = std::chrono::duration_cast<std::chrono::seconds>(
                                      std::chrono::system_clock::now().time_since_epoch())
                                      .count();
    SaveCalibration(path, *calibration);
    std::printf("    wrote %s (%.1f s)\n", path.c_str(), Seconds(start));
  }
  report["delta_l_scale"] = calibration->noise->delta_l_scale;
  report["delta_l_scale_r_squared"] = calibration->noise->r_squared;
  report["exposure_offset_m_per_ms"] = calibration->exposure_offset_m_per_ms;
  report["seconds"] = Seconds(start);
  return std::move(*calibration);
}

// What the controller saw and did in one frame.
struct ControlPoint {
  double time_s = 0.0;
  int integration_register = 0;
  double control_intensity = 0.0;  // Ī as the controller sees it (clipped pixels included)
  double clipped_fraction = 0.0;   // pixels at full-scale intensity
};

ControlPoint ControlSample(const PipelineResult& result, const ControllerOptions& c) {
  ControlPoint p;
  p.time_s = result.stats.timestamp_s;
  p.integration_register = result.stats.integration_time_register;
  p.control_intensity = result.stats.mean_intensity;  // the controlled Ī (one function)
  std::size_t clipped = 0;
  const Image<float>& intensity = result.frame.intensity;
  for (std::size_t i = 0; i < intensity.size(); ++i) {
    clipped += intensity[i] >= c.clipped_intensity ? 1 : 0;
  }
  p.clipped_fraction = static_cast<double>(clipped) /
                       static_cast<double>(std::max<std::size_t>(1, intensity.size()));
  return p;
}

// The controller over the three phases of the demo scene (scenes/demo.yaml: the hand is in
// place 2.5-4.5 s, the lamps are on 6-8.5 s), medians over each phase.
nlohmann::json ReportControllerResponse(const std::vector<ControlPoint>& trace,
                                        const ControllerOptions& c) {
  struct Phase {
    const char* name;
    double from_s, to_s;
  };
  constexpr Phase kPhases[] = {{"empty hall", 0.0, 1.5}, {"hand", 2.5, 4.5}, {"lamps", 6.5, 8.5}};
  const auto median = [](std::vector<double> v) {
    if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  nlohmann::json out = nlohmann::json::array();
  std::printf("    controller (printed law c = c_0 - V_p (I - I_A), c_0 %d, I_A %.0f):",
              c.bias_register, c.target_intensity);
  for (const Phase& phase : kPhases) {
    std::vector<double> reg, intensity, clipped;
    for (const ControlPoint& p : trace) {
      if (p.time_s < phase.from_s || p.time_s >= phase.to_s) continue;
      reg.push_back(p.integration_register);
      intensity.push_back(p.control_intensity);
      clipped.push_back(p.clipped_fraction);
    }
    const double r = median(reg), i = median(intensity), k = median(clipped);
    if (reg.empty()) {
      std::printf(" %s: not reached (--frames);", phase.name);  // a short run
    } else {
      std::printf(" %s: register %.0f, mean intensity %.0f, clipped %.1f%%;", phase.name, r, i,
                  k * 100);
    }
    out.push_back({{"phase", phase.name},
                   {"from_s", phase.from_s},
                   {"to_s", phase.to_s},
                   {"register", Real(r)},
                   {"control_intensity", Real(i)},
                   {"clipped_fraction", Real(k)}});
  }
  std::printf("\n");
  return out;
}

// Statistics of the raw view: the same frame judged with the input flags only.
FrameStats RawStats(const PipelineResult& result, const PipelineOptions& options) {
  MetricFrame raw = result.frame;
  raw.flags = result.input_flags;
  FrameStatsOptions stats = options.stats;
  stats.intensity_roi = options.controller.roi;
  stats.intensity_exclude_flags = options.controller.exclude_flags;
  stats.intensity_clipped = options.controller.clipped_intensity;
  return ComputeFrameStats(raw, stats);
}

// Why the kept pixels that are still wrong (error > bad_error_m) are wrong, by the simulator's
// ground-truth cause; and the error of the kept pixels without the depth-edge (mixed) ones,
// which the accuracy filter is not meant to catch (tof-notes §1; the jump-edge and flying-pixel
// filters are).
struct KeptErrorBreakdown {
  int kept = 0;
  int bad = 0;
  int bad_mixed = 0;
  int bad_scattering = 0;
  int bad_multipath_or_motion = 0;
  int bad_other = 0;  // no cause flagged: noise, wiggling, calibration residual
  double rmse_without_mixed_m = 0.0;
  double median_abs_error_m = 0.0;
};

KeptErrorBreakdown Breakdown(const PipelineResult& result, double bad_error_m) {
  KeptErrorBreakdown b;
  const MetricFrame& f = result.frame;
  if (!f.truth) return b;
  std::vector<double> errors;
  double sum2 = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < f.flags.size(); ++i) {
    const float truth = f.truth->radial_distance_m[i];
    if (!f.flags[i].Valid() || !std::isfinite(truth)) continue;
    const double e = f.radial_distance_m[i] - truth;
    const PixelFlags cause = f.truth->causes[i];
    ++b.kept;
    errors.push_back(std::abs(e));
    if (!cause.Has(Flag::kMixed)) {
      sum2 += e * e;
      ++n;
    }
    if (std::abs(e) <= bad_error_m) continue;
    ++b.bad;
    if (cause.Has(Flag::kMixed)) {
      ++b.bad_mixed;
    } else if (cause.Has(Flag::kScattering)) {
      ++b.bad_scattering;
    } else if (cause.Has(Flag::kMultipath) || cause.Has(Flag::kMotion)) {
      ++b.bad_multipath_or_motion;
    } else {
      ++b.bad_other;
    }
  }
  if (n > 0) b.rmse_without_mixed_m = std::sqrt(sum2 / n);
  if (!errors.empty()) {
    std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
    b.median_abs_error_m = errors[errors.size() / 2];
  }
  return b;
}

nlohmann::json BreakdownJson(const KeptErrorBreakdown& b) {
  return {{"kept_pixels_with_truth", b.kept},
          {"kept_bad", b.bad},
          {"kept_bad_mixed_edge", b.bad_mixed},
          {"kept_bad_scattering", b.bad_scattering},
          {"kept_bad_multipath_or_motion", b.bad_multipath_or_motion},
          {"kept_bad_no_cause_flagged", b.bad_other},
          {"rmse_without_mixed_m", b.rmse_without_mixed_m},
          {"median_abs_error_m", b.median_abs_error_m}};
}

nlohmann::json StatsJson(const FrameStats& s) {
  return {{"sequence", s.sequence},
          {"timestamp_s", s.timestamp_s},
          {"integration_register", s.integration_time_register},
          {"mean_intensity", Real(s.mean_intensity)},
          {"valid_fraction", Real(s.valid_fraction)},
          {"mean_delta_l_m", Real(s.mean_delta_l_m)},
          {"rmse_m", Real(s.rmse_m)},
          {"footprint_rmse_m", Real(s.footprint_rmse_m)},
          {"bad_removed_fraction", Real(s.bad_removed_fraction)},
          {"good_kept_fraction", Real(s.good_kept_fraction)}};
}

void RunDemo(const DemoOptions& o) {
  if (o.frames < 0 || o.frames > 100000) {
    throw Error(ErrorCode::kInvalidArgument,
                "--frames " + std::to_string(o.frames) + " must be in [0, 100000]");
  }
  if (!(o.duration_s >= 0.0 && o.duration_s <= 3600.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "--duration-s " + std::to_string(o.duration_s) + " must be in [0, 3600]");
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
  const double delta_l_scale = calibration.noise->delta_l_scale;
  const ControllerSetpoint setpoint = *calibration.controller_setpoint;
  ControllerOptions paper_law;
  paper_law.kind = ControllerKind::kMayProportional;  // the printed law with the sweep's V_p, c_0
  const ControllerOptions controller = setpoint.Apply(paper_law);
  summary["controller"] = {{"target_intensity", setpoint.target_intensity},
                           {"bias_register", setpoint.bias_register},
                           {"gain_register_per_intensity", setpoint.gain_register_per_intensity},
                           {"amplitude_max_register", setpoint.amplitude_max_register},
                           {"amplitude_max_intensity", setpoint.amplitude_max_intensity},
                           {"intensity_per_register", setpoint.intensity_per_register},
                           {"setpoint_scene", setpoint.scene}};

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
  // The camera sets the pace: a frame takes max(1/30 s, integration + readout), so long
  // exposures give fewer frames in the same camera time.
  const double duration_s = o.duration_s > 0.0 ? o.duration_s : camera.scene().duration_s;
  const int max_frames = o.frames > 0 ? o.frames : 100000;
  std::printf(
      "2/3 run: %.1f s of the 'demo' scene at up to %.0f frames/s%s, controller %s "
      "(I_A %.0f, V_p %.2g, c_0 %d), accuracy filter dL <= %.0f mm\n",
      duration_s, camera.Info().max_frame_rate_hz,
      o.frames > 0 ? (", at most " + std::to_string(o.frames) + " frames").c_str() : "",
      std::string(pipeline.ControllerName()).c_str(), c.target_intensity,
      c.gain_register_per_intensity, c.bias_register, options.filters.accuracy.max_delta_l_m * 1e3);
  std::fflush(stdout);

  const fs::path csv_path = out / "frames.csv";
  std::string csv = "frame," + FrameStatsCsvHeader() + "\n";
  RunStatsAccumulator accumulator;
  PipelineResult result;
  std::vector<ControlPoint> trace;
  std::size_t next_moment = 0;
  nlohmann::json moments = nlohmann::json::array();
  Clock::time_point last_status = run_start;
  for (int k = 0; k < max_frames && camera.NextExposureStartS() < duration_s; ++k) {
    const std::optional<Frame> frame = camera.Grab();
    if (!frame) throw Error(ErrorCode::kInternal, "the simulator stopped delivering frames");
    pipeline.Process(*frame, result);
    camera.SetIntegrationTimeRegister(result.next_integration_register);
    accumulator.Add(result.stats);
    csv += std::to_string(k) + "," + FrameStatsCsvRow(result.stats) + "\n";
    trace.push_back(ControlSample(result, pipeline.options().controller));

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
      const KeptErrorBreakdown kept = Breakdown(result, options.stats.bad_error_m);
      std::printf(
          "      kept: median |error| %s, RMSE without depth-edge pixels %s; of %d kept bad "
          "pixels %d are depth edges (mixed), %d scattering, %d multipath/motion, %d other\n",
          Mm(kept.median_abs_error_m).c_str(), Mm(kept.rmse_without_mixed_m).c_str(), kept.bad,
          kept.bad_mixed, kept.bad_scattering, kept.bad_multipath_or_motion, kept.bad_other);
      moments.push_back({{"name", m.name},
                         {"what", m.what},
                         {"raw", StatsJson(raw)},
                         {"filtered", StatsJson(s)},
                         {"filtered_kept_errors", BreakdownJson(kept)},
                         {"files", {stem + "_raw.png", stem + "_filtered.png", stem + ".ply"}}});
    }
    if (Seconds(last_status) >= 1.0) {
      std::fprintf(stderr, "demo: frame %d  t=%.1f/%.1f s  register %d  valid %.1f%%\n", k + 1,
                   result.stats.timestamp_s, duration_s, result.stats.integration_time_register,
                   result.stats.valid_fraction * 100);
      last_status = Clock::now();
    }
  }
  WriteFileAtomically(csv_path, csv);
  const RunSummary run = accumulator.Summary();
  const double run_s = Seconds(run_start);
  // Camera time: frames per second of the simulated camera (its timestamps), which the
  // controller's registers allowed; the processing rate is what this machine managed.
  const double camera_fps = trace.size() > 1 ? static_cast<double>(trace.size() - 1) /
                                                   (trace.back().time_s - trace.front().time_s)
                                             : std::numeric_limits<double>::quiet_NaN();
  std::printf(
      "    %llu frames in %.1f s of camera time (%.1f frames/s; registers <= %d) and %.1f s "
      "of computing (%.1f frames/s incl. simulation): mean valid %.1f%%, mean dL %s, RMSE of "
      "kept pixels %s (%s against the footprint truth: an edge pixel reading either of its "
      "surfaces counts as right), bad pixels removed %.1f%%, good kept %.1f%%\n",
      static_cast<unsigned long long>(run.frames),
      trace.size() > 1 ? trace.back().time_s - trace.front().time_s : 0.0, camera_fps,
      c.max_register, run_s, run.frames / run_s, run.mean_valid_fraction * 100,
      Mm(run.mean_delta_l_m).c_str(), Mm(run.rmse_m).c_str(), Mm(run.footprint_rmse_m).c_str(),
      run.bad_removed_fraction * 100, run.good_kept_fraction * 100);
  summary["controller_response"] = ReportControllerResponse(trace, c);

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
  summary["footprint_rmse_m"] = Real(run.footprint_rmse_m);
  summary["bad_removed_fraction"] = Real(run.bad_removed_fraction);
  summary["good_kept_fraction"] = Real(run.good_kept_fraction);
  summary["bad_error_m"] = options.stats.bad_error_m;
  summary["mean_frames_per_s"] = Real(run.frames / run_s);
  summary["camera_frames_per_s"] = Real(camera_fps);
  summary["frame_rate_limit_hz"] = c.frame_rate_hz;
  summary["moments"] = moments;
  summary["pan"] = pan_report;
  summary["elapsed_s"] = Seconds(start);
  WriteFileAtomically(out / "summary.json", summary.dump(2) + "\n");

  std::printf("\ndone in %.1f s. Look at %s/:\n", Seconds(start), o.out.c_str());
  if (fs::exists(out / "moment_before_raw.png")) {
    std::printf(
        "  moment_before_raw.png next to moment_before_filtered.png: the accuracy filter keeps "
        "the well-lit near objects and removes the noisy far hall (its dL is large)\n");
  }
  if (fs::exists(out / "moment_hand_raw.png")) {
    std::printf(
        "  moment_hand_*.png: the clipped hand has no phase (black in both); the filter removes "
        "the far hall, part of the scattering halo around the fingers survives (docs/demo.md)\n");
  }
  if (moments.empty()) {
    std::printf("  (no moment_* files: --frames ended the run before the first moment)\n");
  } else {
    std::printf(
        "  moment_{before,hand,lamps}_{raw,filtered}.png  false colour, yellow 0 m -> red -> "
        "magenta -> blue L = 7.5 m, black = rejected (the moments the run reached)\n"
        "  moment_*.ply     the kept points of those frames (camera frame)\n");
  }
  std::printf(
      "  panorama_{raw,filtered}.png  the 180 deg strip, left = +90 deg; .ply: its cloud (pan "
      "unit's base frame)\n"
      "  frames.csv       one row per frame (register, intensity, valid, dL, RMSE, bad removed, "
      "good kept)\n"
      "  summary.json     every number printed here; calibration.yaml the calibration (offsets, "
      "exposure offset, distance correction, noise scale, controller set point)\n");
  std::printf(
      "What the numbers mean:\n"
      "  register, intensity  the P-controller's integration-time register and the mean "
      "intensity it controls (clipped pixels included). I_A and c_0 come from the hall's "
      "integration-time sweep, so it holds c_0 there; the hand and the lamps raise the "
      "intensity and it backs off by V_p (I - I_A) registers: the printed position law, "
      "which stops short of unclipping the hand (docs/controllers.md)\n"
      "  dL                   predicted 1-sigma noise of a pixel (eq. 2 x the noise "
      "calibration's scale); valid = kept by the saturation filter and dL <= %.0f mm\n"
      "  bad removed / good kept  pixels whose error against the simulator's truth is above / "
      "within %.0f mm and that the filters removed / kept\n"
      "  RMSE of kept pixels  dominated by a few depth-edge (mixed) pixels metres off, which "
      "the accuracy filter is not meant to remove; the median |error| and the RMSE without "
      "depth edges describe the rest\n",
      options.filters.accuracy.max_delta_l_m * 1e3, options.stats.bad_error_m * 1e3);
}

void SetupDemoCommand(CLI::App& app) {
  auto o = std::make_shared<DemoOptions>();
  CLI::App* sub = app.add_subcommand(
      "demo", "The paper's system on the simulated SR-2: calibrate, run, pan (make demo)");
  sub->add_option("--out", o->out, "Output directory")->capture_default_str();
  sub->add_option("--seed", o->seed, "Simulator noise seed")
      ->check(kNonNegative)
      ->capture_default_str();
  sub->add_option("--duration-s", o->duration_s,
                  "Camera time of the demo sequence, s (0 = the scene's 10 s)")
      ->capture_default_str();
  sub->add_option("--frames", o->frames, "At most this many frames of the sequence (0 = no cap)")
      ->capture_default_str();
  sub->add_option("--threads", o->threads, "Simulator worker threads")->capture_default_str();
  sub->add_flag("--recalibrate", o->recalibrate, "Calibrate even when a cached file fits");
  sub->callback([o] { RunDemo(*o); });
}

TOFCAM_REGISTER_COMMAND("demo", SetupDemoCommand);

}  // namespace
}  // namespace tofcam::cli

// `tofcam calibrate`: the per-pixel distance calibration of paper section II-B against a camera
// facing a flat wall, optionally followed by a wall sweep for the distance-dependent correction.
// Progress goes to stderr, the summary to stdout, the calibration to --out (docs/calibration.md).
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "camera_source.h"
#include "commands.h"
#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/calibration/scattering_calibration.h"
#include "tofcam/core/error.h"
#include "tofcam/io/calibration_file.h"

namespace tofcam::cli {
namespace {

struct CalibrateOptions {
  std::string camera;
  std::string out;
  double wall_distance_m = 0.0;
  int frames = 50;
  bool sweep = false;
  double sweep_from_m = 0.5;
  double sweep_to_m = 7.0;
  double sweep_step_m = 0.25;
  int sweep_frames = 10;
  double warmup_max_drift_mm_per_s = 0.05;
  int warmup_max_frames = 9000;
  std::string controller = "vendor-histogram";
  int exposure_offset_frames = 20;  // 0: no exposure-offset measurement
  bool noise = false;
  int noise_frames = 30;
  bool setpoint = false;
  std::string setpoint_camera;  // "" = --camera
  int setpoint_steps = 32;
  std::string scattering_target;  // camera with the bright card; "" = no scattering calibration
  int scattering_frames = 8;
  int scattering_register = 0;
  bool wall = false;  // --wall-distance-m given
  CameraSourceOptions source;
};

// The value of `key=` in a camera spec's query ("sim:wall?distance_m=2&x=1"), if present.
std::string::size_type FindParameter(const std::string& spec, const std::string& key,
                                     std::string::size_type* value_end) {
  const auto query = spec.find('?');
  if (query == std::string::npos) return std::string::npos;
  std::string::size_type at = query + 1;
  while (at < spec.size()) {
    const auto end = std::min(spec.find('&', at), spec.size());
    if (spec.compare(at, key.size() + 1, key + "=") == 0) {
      *value_end = end;
      return at + key.size() + 1;
    }
    at = end + 1;
  }
  return std::string::npos;
}

// `spec` with distance_m set to `distance_m` (replaced or appended).
std::string WithWallDistance(const std::string& spec, double distance_m) {
  char value[32];
  std::snprintf(value, sizeof value, "%.6g", distance_m);
  std::string::size_type end = 0;
  const auto start = FindParameter(spec, "distance_m", &end);
  if (start != std::string::npos) return spec.substr(0, start) + value + spec.substr(end);
  return spec + (spec.find('?') == std::string::npos ? "?" : "&") + "distance_m=" + value;
}

void Progress(const CalibrationProgress& p) {
  std::fprintf(stderr, "calibrate: %-9s %4d/%-4d %s\n", std::string(p.phase).c_str(), p.frame,
               p.total, p.message.c_str());
}

// A calibration that only carries camera-level measurements (noise, set point): zero offsets,
// so eq. 1 is the identity; frames_averaged 0 and wall distance 0 mark it (docs/calibration.md).
OffsetCalibration MeasurementsOnly(const CameraInfo& info) {
  OffsetCalibration c;
  c.camera_model = info.model;
  c.width = info.width();
  c.height = info.height();
  c.modulation_frequency_hz = info.modulation_frequency_hz;
  c.created_unix_s = static_cast<std::int64_t>(std::time(nullptr));
  c.offset_m = Image<float>(c.width, c.height, 0.0f);
  return c;
}

void RunNoiseCalibration(Camera& camera, OffsetCalibration& calibration, int frames) {
  NoiseCalibrationOptions options;
  options.frames = frames;
  DeltaLScaleFit fit;
  NoiseModelReport model;
  calibration.noise = CalibrateNoise(camera, options, Progress, &fit, &model);
  std::printf(
      "noise calibration: sigma = %.4g x dL of eq. 2 (median sigma/dL %.4g, R^2 %.3f, %d "
      "pixels, %d static frames at register %d)\n",
      fit.scale, fit.median_ratio, fit.r_squared, fit.pixels_used, fit.frames,
      camera.IntegrationTimeRegister());
  if (model.fit) {
    const NoiseModelFit& m = *model.fit;
    std::printf(
        "noise model (%s): held-out Spearman rho %.3f (eq. 2 %.3f), largest decile error "
        "%.0f %% (eq. 2 %.0f %%) on %d held-out pixels\n",
        m.features.c_str(), m.fitted.spearman, m.eq2.spearman, 100 * m.fitted.max_decile_error,
        100 * m.eq2.max_decile_error, m.held_out_pixels);
  }
  std::printf("noise model %s\n", model.note.c_str());
}

// The point-spread of the camera's optics from the wall (--camera) and the same wall with a
// bright card near the lens (--scattering-target).
void RunScatteringCalibration(const CalibrateOptions& o, OffsetCalibration& calibration) {
  std::unique_ptr<Camera> wall = OpenCamera(o.camera, o.source);
  std::unique_ptr<Camera> card = OpenCamera(o.scattering_target, o.source);
  CheckCalibrationMatches(calibration, card->Info());
  ScatteringCalibrationOptions options;
  options.frames = o.scattering_frames;
  options.integration_time_register = o.scattering_register;
  calibration.scattering = CalibrateScattering(*wall, *card, options, Progress);
  const ScatteringCalibration& s = *calibration.scattering;
  std::printf(
      "scattering point-spread (register %d, %d frames per scene, %d card pixels, %d fit "
      "pixels, %.3f of the stray light explained):",
      s.integration_time_register, s.frames, s.target_pixels, s.fit_pixels, s.explained_fraction);
  for (const ScatteringLobe& l : s.lobes) {
    std::printf(" weight %.4g at sigma %.3g px;", l.weight, l.sigma_px);
  }
  std::printf("\n");
}

// The camera of --setpoint, opened and checked before any long phase runs, so that a camera
// without a settable integration time or a bad --setpoint-steps fails at once, not after minutes.
struct SetpointSource {
  std::string spec;
  std::unique_ptr<Camera> camera;
  IntegrationSweepOptions sweep;
  SetpointOptions choose;
};

SetpointSource OpenSetpointSource(const CalibrateOptions& o) {
  SetpointSource s;
  s.spec = o.setpoint_camera.empty() ? o.camera : o.setpoint_camera;
  if (o.setpoint_steps < 3 || o.setpoint_steps > 1000) {
    throw Error(ErrorCode::kInvalidArgument,
                "--setpoint-steps " + std::to_string(o.setpoint_steps) + " must be in [3, 1000]");
  }
  s.camera = OpenCamera(s.spec, o.source);
  const CameraInfo& info = s.camera->Info();
  // Register 0 (SR-3000/4000: the shortest time) cannot carry the paper's law, which the
  // controllers clamp to >= 1 as well.
  const int lo = std::max(1, info.min_integration_register);
  const int hi = info.max_integration_register;
  if (hi <= lo) {
    throw Error(ErrorCode::kInvalidArgument,
                "--setpoint needs a camera with a settable integration time; " + s.spec +
                    " has integration registers " + std::to_string(info.min_integration_register) +
                    ".." + std::to_string(hi));
  }
  s.sweep.from_register = lo;
  s.sweep.to_register = hi;
  s.sweep.steps = o.setpoint_steps;
  s.sweep.Validate();
  s.choose.min_register = lo;
  s.choose.max_register = hi;
  s.choose.Validate();
  return s;
}

void SetpointSweep(SetpointSource& source, OffsetCalibration& calibration) {
  const std::string& spec = source.spec;
  Camera& camera = *source.camera;
  CheckCalibrationMatches(calibration, camera.Info());
  const std::vector<IntegrationSweepPoint> points =
      SweepIntegrationTime(camera, source.sweep, Progress);
  ControllerSetpoint setpoint = ChooseSetpoint(points, source.choose);
  setpoint.scene = spec;
  std::printf("\nintegration-time sweep of %s (paper fig. 3):\n%8s %10s %10s %10s\n", spec.c_str(),
              "register", "intensity", "amplitude", "saturated");
  for (const IntegrationSweepPoint& p : points) {
    std::printf(
        "%8d %10.0f %10.0f %9.1f%%%s\n", p.integration_register, p.mean_intensity, p.mean_amplitude,
        p.saturated_fraction * 100,
        p.integration_register == setpoint.amplitude_max_register ? "  <- amplitude max" : "");
  }
  std::printf(
      "controller set point: amplitude maximum at register %d (mean intensity %.0f) -> I_A = "
      "%.0f, c_0 = %d (%.0f intensity units per register), V_p = %.3g\n",
      setpoint.amplitude_max_register, setpoint.amplitude_max_intensity, setpoint.target_intensity,
      setpoint.bias_register, setpoint.intensity_per_register,
      setpoint.gain_register_per_intensity);
  calibration.controller_setpoint = setpoint;
}

// A new wall calibration replacing --out keeps the camera-level measurements of the file it
// replaces (noise scale, controller set point) when that file fits the camera and they are not
// measured again in this run; it says so either way.
void KeepPreviousMeasurements(const CalibrateOptions& o, const CameraInfo& info,
                              OffsetCalibration& calibration) {
  if (!std::filesystem::exists(o.out)) return;
  try {
    const OffsetCalibration previous = LoadCalibration(o.out);
    CheckCalibrationMatches(previous, info);
    if (!o.noise && previous.noise) {
      calibration.noise = previous.noise;
      std::printf("kept the noise calibration of the previous %s\n", o.out.c_str());
    }
    if (!o.setpoint && previous.controller_setpoint) {
      calibration.controller_setpoint = previous.controller_setpoint;
      std::printf("kept the controller set point of the previous %s\n", o.out.c_str());
    }
    if (o.scattering_target.empty() && previous.scattering) {
      calibration.scattering = previous.scattering;
      std::printf("kept the scattering point-spread of the previous %s\n", o.out.c_str());
    }
  } catch (const Error& e) {
    std::printf("replacing %s, whose measurements do not carry over (%s)\n", o.out.c_str(),
                e.what());
  }
}

void RunCalibrate(const CalibrateOptions& o) {
  const bool scattering = !o.scattering_target.empty();
  if (!o.wall && !o.noise && !o.setpoint && !scattering) {
    throw Error(ErrorCode::kInvalidArgument,
                "nothing to calibrate: give --wall-distance-m (wall calibration), --noise, "
                "--setpoint and/or --scattering-target");
  }
  if (scattering) {
    ScatteringCalibrationOptions check;
    check.frames = o.scattering_frames;
    check.integration_time_register = o.scattering_register;
    try {
      check.Validate();
    } catch (const Error& e) {
      throw Error(e.code(),
                  std::string("--scattering-frames / --scattering-register: ") + e.what());
    }
  }
  if (o.noise_frames < 3 || o.noise_frames > 100000) {
    throw Error(ErrorCode::kInvalidArgument,
                "--noise-frames " + std::to_string(o.noise_frames) + " must be in [3, 100000]");
  }
  if (o.exposure_offset_frames < 0 || o.exposure_offset_frames > 100000) {
    throw Error(ErrorCode::kInvalidArgument, "--exposure-offset-frames " +
                                                 std::to_string(o.exposure_offset_frames) +
                                                 " must be in [0, 100000]");
  }
  const std::filesystem::path out_dir = std::filesystem::path(o.out).parent_path();
  if (!out_dir.empty() && !std::filesystem::is_directory(out_dir)) {
    throw Error(ErrorCode::kIo,
                "--out " + o.out + ": directory " + out_dir.string() + " does not exist");
  }
  std::optional<SetpointSource> setpoint_source;
  if (o.setpoint) setpoint_source = OpenSetpointSource(o);
  // The sources the later phases open are opened once now: a wrong spec must fail before the
  // minutes of the wall calibration, not after them with nothing written.
  if (scattering) {
    try {
      (void)OpenCamera(o.scattering_target, o.source);
    } catch (const Error& e) {
      throw Error(e.code(), std::string("--scattering-target: ") + e.what());
    }
  }
  if (o.wall && o.sweep) {
    try {
      (void)OpenCamera(WithWallDistance(o.camera, o.sweep_from_m), o.source);
    } catch (const Error& e) {
      throw Error(e.code(),
                  std::string("--sweep moves the wall, so --camera must be a simulated scene "
                              "with a distance_m parameter (e.g. sim:wall): ") +
                      e.what());
    }
  }
  if (!o.wall) {
    // Measurements only: added to the calibration in --out, or to a new one with zero offsets.
    std::unique_ptr<Camera> camera = OpenCamera(o.camera, o.source);
    OffsetCalibration calibration;
    if (std::filesystem::exists(o.out)) {
      calibration = LoadCalibration(o.out);
      CheckCalibrationMatches(calibration, camera->Info());
      std::printf("updating %s\n", o.out.c_str());
    } else {
      calibration = MeasurementsOnly(camera->Info());
      std::printf(
          "%s does not exist: it will hold zero offsets (eq. 1 = identity) and the "
          "measurements below\n",
          o.out.c_str());
    }
    if (o.noise) RunNoiseCalibration(*camera, calibration, o.noise_frames);
    camera.reset();
    if (scattering) RunScatteringCalibration(o, calibration);
    if (setpoint_source) SetpointSweep(*setpoint_source, calibration);
    SaveCalibration(o.out, calibration);
    std::printf("wrote %s\n", o.out.c_str());
    return;
  }
  if (!(o.wall_distance_m > 0.0) || !std::isfinite(o.wall_distance_m)) {
    throw Error(ErrorCode::kInvalidArgument,
                "--wall-distance-m " + std::to_string(o.wall_distance_m) + " must be > 0");
  }
  // A spec that names its own wall distance must agree with --wall-distance-m.
  std::string::size_type end = 0;
  const auto at = FindParameter(o.camera, "distance_m", &end);
  if (at != std::string::npos) {
    const std::string given = o.camera.substr(at, end - at);
    char* parsed_end = nullptr;
    const double spec_distance = std::strtod(given.c_str(), &parsed_end);
    if (parsed_end == given.c_str() || std::abs(spec_distance - o.wall_distance_m) > 1e-9) {
      throw Error(ErrorCode::kInvalidArgument, "--camera says distance_m=" + given +
                                                   " but --wall-distance-m is " +
                                                   std::to_string(o.wall_distance_m));
    }
  }

  // The option is in mm/s, the procedure's check speaks of m/s: checked here in the option's
  // unit so that the message names what the user typed.
  if (!(o.warmup_max_drift_mm_per_s > 0.0 && o.warmup_max_drift_mm_per_s <= 1000.0)) {
    throw Error(ErrorCode::kInvalidArgument, "--warmup-max-drift-mm-per-s " +
                                                 std::to_string(o.warmup_max_drift_mm_per_s) +
                                                 " must be in (0, 1000]");
  }
  WallCalibrationOptions wall;
  wall.wall_distance_m = o.wall_distance_m;
  wall.frames = o.frames;
  wall.warmup_max_drift_m_per_s = o.warmup_max_drift_mm_per_s * 1e-3;
  wall.warmup_max_frames = o.warmup_max_frames;
  if (o.exposure_offset_frames == 0) {
    wall.exposure_offset_fractions.clear();
  } else {
    wall.exposure_offset_frames = o.exposure_offset_frames;
  }
  if (o.controller != ControllerKindName(wall.controller.kind)) {
    wall.controller = ControllerOptions{};
    wall.controller.kind = ParseControllerKind(o.controller);
  }
  if (wall.controller.kind == ControllerKind::kFixed) {
    // A stated exposure: the register the camera is opened with.
    if (o.source.integration_time_register <= 0) {
      throw Error(ErrorCode::kInvalidArgument,
                  "--controller fixed calibrates at a stated exposure: give it with "
                  "--integration-register N");
    }
    wall.controller.max_register =
        std::max(wall.controller.max_register, o.source.integration_time_register);
    wall.controller.bias_register = o.source.integration_time_register;
  }
  SweepOptions sweep;
  sweep.from_m = o.sweep_from_m;
  sweep.to_m = o.sweep_to_m;
  sweep.step_m = o.sweep_step_m;
  sweep.frames_per_distance = o.sweep_frames;
  sweep.wall = wall;
  wall.Validate();
  if (o.sweep) sweep.Validate();

  // Fail before minutes of calibration, not after: the output directory must exist (checked
  // above) and the sweep must stay inside the camera's unambiguous range.
  std::unique_ptr<Camera> camera = OpenCamera(o.camera, o.source);
  const CameraInfo camera_info = camera->Info();
  const double range_m = camera_info.unambiguous_range_m();
  // A recording or an import replays its registers: the exposure control and the exposure-
  // offset sweep cannot run on it (they used to fail with "cannot change the integration time"
  // after the averaging). What does work is said now.
  {
    const int recorded = camera->IntegrationTimeRegister();
    std::string refusal;  // the source's own reason, when it cannot change the register
    try {
      const int other =
          recorded > camera_info.min_integration_register ? recorded - 1 : recorded + 1;
      camera->SetIntegrationTimeRegister(other);
      camera->SetIntegrationTimeRegister(recorded);
    } catch (const Error& e) {
      refusal = e.what();
    }
    if (!refusal.empty() && recorded <= 0) {
      // An import or a ROS 2 driver's stream: no register to calibrate at.
      throw Error(ErrorCode::kUnsupported,
                  "--camera " + o.camera + " reports no integration-time register (" + refusal +
                      "): a wall calibration needs a camera whose exposure it can set, or a "
                      "recording of one");
    }
    if (!refusal.empty() &&
        (wall.controller.kind != ControllerKind::kFixed ||
         o.source.integration_time_register != recorded || o.exposure_offset_frames > 0)) {
      throw Error(ErrorCode::kUnsupported,
                  "--camera " + o.camera + " cannot change its integration time (" + refusal +
                      "): calibrate it at its register with --controller fixed "
                      "--integration-register " +
                      std::to_string(recorded) +
                      " --exposure-offset-frames 0 (and frames enough for the warm-up window and "
                      "--frames)");
    }
  }
  if (o.sweep && o.sweep_to_m >= range_m) {
    throw Error(ErrorCode::kInvalidArgument,
                "--sweep-to-m " + std::to_string(o.sweep_to_m) +
                    " must be below the unambiguous range L = " + std::to_string(range_m) + " m");
  }
  WallCalibrationReport report;
  OffsetCalibration calibration = CalibrateOffsets(*camera, wall, Progress, &report);
  std::printf(
      "wall calibration at %.3f m: register %d (%.0f us), %d exposure + %d warm-up "
      "frames, drift %.4f mm/s\n",
      o.wall_distance_m, report.integration_register, calibration.integration_time_us,
      report.exposure_frames, report.warmup_frames, report.drift_m_per_s * 1e3);
  if (report.exposure_at_bound != 0) {
    std::fprintf(stderr,
                 "calibrate: warning: the exposure controller stopped at its %s register %d: "
                 "the wall is too %s for its set point and the offsets were measured at that "
                 "bound. State an exposure with --controller fixed --integration-register N, "
                 "or move the wall %s.\n",
                 report.exposure_at_bound > 0 ? "largest" : "smallest", report.integration_register,
                 report.exposure_at_bound > 0 ? "dark" : "bright",
                 report.exposure_at_bound > 0 ? "closer" : "further away");
  }
  std::printf(
      "offsets: mean %.2f mm, rms %.2f mm, noise %.2f mm per frame (%.2f mm after %d "
      "frames), %d uncalibrated pixels\n",
      report.mean_offset_m * 1e3, report.offset_rms_m * 1e3, report.noise_sigma_m * 1e3,
      report.noise_sigma_m * 1e3 / std::sqrt(static_cast<double>(o.frames)), o.frames,
      report.uncalibrated_pixels);
  // A camera's own offsets are centimetres to a few decimetres; half a metre means the wall is
  // not where --wall-distance-m says, or the view is not the wall. Said, not refused: a camera
  // may really be that far off before its first calibration.
  if (std::abs(report.mean_offset_m) > 0.5 || report.offset_rms_m > 0.5) {
    std::fprintf(stderr,
                 "calibrate: warning: offsets of %.0f mm mean and %.0f mm rms are far beyond a "
                 "camera's fixed-pattern offsets: is the wall at %.3f m (--wall-distance-m), flat, "
                 "perpendicular and filling the view?\n",
                 report.mean_offset_m * 1e3, report.offset_rms_m * 1e3, o.wall_distance_m);
  }
  if (report.exposure_registers.size() >= 2) {
    std::printf("exposure offset: %.4f mm per ms of integration time (shift",
                calibration.exposure_offset_m_per_ms * 1e3);
    for (std::size_t k = 0; k < report.exposure_registers.size(); ++k) {
      std::printf(" %+.2f mm at register %d", report.exposure_shift_m[k] * 1e3,
                  report.exposure_registers[k]);
    }
    std::printf("); per-pixel slopes spread %.4f mm/ms, noise alone %.4f mm/ms\n",
                report.exposure_pixel_slope_sd_m_per_ms * 1e3,
                report.exposure_pixel_slope_noise_m_per_ms * 1e3);
  } else {
    std::printf("exposure offset: not measured (0)\n");
  }
  if (o.noise) RunNoiseCalibration(*camera, calibration, o.noise_frames);

  if (o.sweep) {
    const bool has_kind = o.camera.find(':') != std::string::npos;
    if (!has_kind) {
      throw Error(ErrorCode::kInvalidArgument, "--camera '" + o.camera + "' has no kind");
    }
    camera.reset();
    std::unique_ptr<Camera> moved;
    const WallCameraSource source = [&](double distance_m) -> Camera& {
      moved.reset();
      moved = OpenCamera(WithWallDistance(o.camera, distance_m), o.source);
      return *moved;
    };
    SweepReport sweep_report;
    calibration = CalibrateDistanceCorrection(calibration, source, sweep, Progress, &sweep_report);
    std::printf("\n%8s %8s %6s %9s %12s %11s %11s\n", "wall_m", "set", "reg", "raw_mm",
                "offsets_mm", "full_mm", "noise_mm");
    for (const SweepDistanceResult& d : sweep_report.distances) {
      std::printf("%8.3f %8s %6d %9.2f %12.2f %11.2f %11.2f\n", d.wall_distance_m,
                  d.held_out ? "held-out" : "fit", d.integration_register, d.rms_raw_m * 1e3,
                  d.rms_before_m * 1e3, d.rms_after_m * 1e3, d.noise_floor_m * 1e3);
    }
    std::printf(
        "held-out RMS error: %.2f mm with the offset matrix (eq. 1), %.2f mm with the "
        "distance correction (noise floor %.2f mm)\n",
        sweep_report.held_out_rms_before_m * 1e3, sweep_report.held_out_rms_after_m * 1e3,
        sweep_report.held_out_noise_floor_m * 1e3);
  }
  KeepPreviousMeasurements(o, camera_info, calibration);
  camera.reset();
  if (scattering) RunScatteringCalibration(o, calibration);
  if (setpoint_source) SetpointSweep(*setpoint_source, calibration);
  SaveCalibration(o.out, calibration);
  std::printf("wrote %s\n", o.out.c_str());
}

void SetupCalibrateCommand(CLI::App& app) {
  auto o = std::make_shared<CalibrateOptions>();
  CLI::App* sub = app.add_subcommand(
      "calibrate", "Per-pixel distance calibration against a flat wall (paper section II-B)");
  sub->add_option("--camera", o->camera,
                  "Camera facing a wall, e.g. sim:wall?distance_m=2; " + CameraSourceHelp())
      ->required();
  sub->add_option("--wall-distance-m", o->wall_distance_m,
                  "Perpendicular camera-to-wall distance, m (the wall calibration; without it "
                  "only --noise / --setpoint are measured and added to --out)");
  sub->add_option("--out", o->out, "Calibration file to write (YAML, docs/calibration.md)")
      ->required();
  sub->add_option("--frames", o->frames, "Frames averaged at the wall (1..100000)")
      ->capture_default_str();
  sub->add_flag("--sweep", o->sweep,
                "Also sweep the wall over --sweep-from-m..--sweep-to-m for the distance-dependent "
                "correction (the camera spec's distance_m is set per distance)");
  sub->add_option("--sweep-from-m", o->sweep_from_m, "First sweep distance, m (implies --sweep)")
      ->capture_default_str();
  sub->add_option("--sweep-to-m", o->sweep_to_m, "Last sweep distance, m (implies --sweep)")
      ->capture_default_str();
  sub->add_option("--sweep-step-m", o->sweep_step_m, "Sweep spacing, m (implies --sweep)")
      ->capture_default_str();
  sub->add_option("--sweep-frames", o->sweep_frames, "Frames averaged per sweep distance")
      ->capture_default_str();
  sub->add_option("--warmup-max-drift-mm-per-s", o->warmup_max_drift_mm_per_s,
                  "Warm-up ends when the mean distance drifts slower than this")
      ->capture_default_str();
  sub->add_option("--warmup-max-frames", o->warmup_max_frames,
                  "Give up when the drift has not settled after this many frames")
      ->capture_default_str();
  sub->add_option(
         "--controller", o->controller,
         "Exposure controller: vendor-histogram, may-incremental, may-proportional, model-based, "
         "fixed")
      ->capture_default_str();
  sub->add_option("--exposure-offset-frames", o->exposure_offset_frames,
                  "Frames per integration time for the exposure offset (0 = do not measure)")
      ->capture_default_str();
  sub->add_flag("--noise", o->noise,
                "Noise calibration from static frames of --camera: eq. 2's scale and, with >= 4 "
                "frames, a fitted noise model (docs/noise_model.md; stored in --out)");
  sub->add_option("--noise-frames", o->noise_frames, "Static frames for --noise (3..100000)")
      ->capture_default_str();
  sub->add_option("--scattering-target", o->scattering_target,
                  "The same wall as --camera with a small bright card near the lens, e.g. "
                  "sim:calibration/scattering-card: measures the optics' scattering point-spread "
                  "for the pipeline's compensation (docs/beyond.md; stored in --out)");
  sub->add_option("--scattering-frames", o->scattering_frames,
                  "Frames per scene for --scattering-target (1..10000)")
      ->capture_default_str();
  sub->add_option("--scattering-register", o->scattering_register,
                  "Register for --scattering-target; 0 = the longest at which the card does not "
                  "clip")
      ->capture_default_str();
  sub->add_flag("--setpoint", o->setpoint,
                "Integration-time sweep of the working scene: the controller's I_A, c_0, V_p "
                "(stored in --out)");
  sub->add_option("--setpoint-camera", o->setpoint_camera,
                  "Camera looking at the working scene for --setpoint (default: --camera), "
                  "e.g. sim:pavilion");
  sub->add_option("--setpoint-steps", o->setpoint_steps, "Registers in the sweep (3..1000)")
      ->capture_default_str();
  sub->add_option("--integration-register", o->source.integration_time_register,
                  "Integration-time register to open the camera with (0 = its default)")
      ->capture_default_str();
  sub->add_option("--seed", o->source.seed, "Simulator noise seed")
      ->check(kNonNegative)
      ->capture_default_str();
  AddRos2DomainOption(sub, o->source.ros2_domain);
  sub->add_option("--camera-model", o->source.camera_model, "Simulator camera model");
  sub->callback([o, sub] {
    CalibrateOptions run = *o;
    for (const char* name : {"--sweep-from-m", "--sweep-to-m", "--sweep-step-m"}) {
      if (sub->count(name) > 0) run.sweep = true;
    }
    run.wall = sub->count("--wall-distance-m") > 0;
    if (sub->count("--setpoint-camera") > 0) run.setpoint = true;
    if (run.sweep && !run.wall) {
      throw Error(ErrorCode::kInvalidArgument, "--sweep needs --wall-distance-m");
    }
    RunCalibrate(run);
  });
}

TOFCAM_REGISTER_COMMAND("calibrate", SetupCalibrateCommand);

}  // namespace
}  // namespace tofcam::cli

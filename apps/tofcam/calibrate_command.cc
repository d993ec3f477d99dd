// `tofcam calibrate`: the per-pixel distance calibration of paper section II-B against a camera
// facing a flat wall, optionally followed by a wall sweep for the distance-dependent correction.
// Progress goes to stderr, the summary to stdout, the calibration to --out (docs/calibration.md).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

#include "camera_source.h"
#include "commands.h"
#include "tofcam/calibration/calibration_procedure.h"
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

void RunCalibrate(const CalibrateOptions& o) {
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

  WallCalibrationOptions wall;
  wall.wall_distance_m = o.wall_distance_m;
  wall.frames = o.frames;
  wall.warmup_max_drift_m_per_s = o.warmup_max_drift_mm_per_s * 1e-3;
  wall.warmup_max_frames = o.warmup_max_frames;
  if (o.controller != ControllerKindName(wall.controller.kind)) {
    wall.controller = ControllerOptions{};
    wall.controller.kind = ParseControllerKind(o.controller);
  }
  SweepOptions sweep;
  sweep.from_m = o.sweep_from_m;
  sweep.to_m = o.sweep_to_m;
  sweep.step_m = o.sweep_step_m;
  sweep.frames_per_distance = o.sweep_frames;
  sweep.wall = wall;
  wall.Validate();
  if (o.sweep) sweep.Validate();

  // Fail before minutes of calibration, not after: the output directory must exist and the
  // sweep must stay inside the camera's unambiguous range.
  const std::filesystem::path out_dir = std::filesystem::path(o.out).parent_path();
  if (!out_dir.empty() && !std::filesystem::is_directory(out_dir)) {
    throw Error(ErrorCode::kIo,
                "--out " + o.out + ": directory " + out_dir.string() + " does not exist");
  }
  std::unique_ptr<Camera> camera = OpenCamera(o.camera, o.source);
  const double range_m = camera->Info().unambiguous_range_m();
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
  std::printf(
      "offsets: mean %.2f mm, rms %.2f mm, noise %.2f mm per frame (%.2f mm after %d "
      "frames), %d uncalibrated pixels\n",
      report.mean_offset_m * 1e3, report.offset_rms_m * 1e3, report.noise_sigma_m * 1e3,
      report.noise_sigma_m * 1e3 / std::sqrt(static_cast<double>(o.frames)), o.frames,
      report.uncalibrated_pixels);

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
                  "Perpendicular camera-to-wall distance, m")
      ->required();
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
  sub->add_option("--controller", o->controller,
                  "Exposure controller: vendor-histogram, may-incremental, may-proportional, "
                  "fixed")
      ->capture_default_str();
  sub->add_option("--seed", o->source.seed, "Simulator noise seed")->capture_default_str();
  sub->add_option("--camera-model", o->source.camera_model, "Simulator camera model");
  sub->callback([o, sub] {
    CalibrateOptions run = *o;
    for (const char* name : {"--sweep-from-m", "--sweep-to-m", "--sweep-step-m"}) {
      if (sub->count(name) > 0) run.sweep = true;
    }
    RunCalibrate(run);
  });
}

TOFCAM_REGISTER_COMMAND("calibrate", SetupCalibrateCommand);

}  // namespace
}  // namespace tofcam::cli

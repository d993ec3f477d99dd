// `tofcam run`: camera -> pipeline -> controller in a loop (docs/pipeline.md). Frame t's
// controller output is set on the camera before frame t + 1 is grabbed. Ctrl-C finishes the
// current frame, writes the outputs and exits 0. Status on stderr about once a second; per-frame
// statistics in <out>/frames.csv, the run in <out>/summary.json.
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <utility>

#include "camera_source.h"
#include "commands.h"
#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/io/cloud_io.h"
#include "tofcam/io/importers.h"
#include "tofcam/io/pipeline_config.h"
#include "tofcam/io/png.h"
#include "tofcam/pipeline/pipeline.h"
#ifdef TOFCAM_WITH_ROS2
#include "tofcam/ros2/publisher.h"
#include "tofcam/ros2/ros2_camera.h"
#endif

namespace tofcam::cli {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::atomic<bool> g_interrupted{false};

extern "C" void OnSigint(int /*signal*/) { g_interrupted.store(true); }

// Installs the SIGINT handler for the lifetime of the object and restores the previous one.
class SigintGuard {
 public:
  SigintGuard() {
    g_interrupted.store(false);
    previous_ = std::signal(SIGINT, OnSigint);
  }
  ~SigintGuard() { std::signal(SIGINT, previous_ == SIG_ERR ? SIG_DFL : previous_); }
  SigintGuard(const SigintGuard&) = delete;
  SigintGuard& operator=(const SigintGuard&) = delete;

 private:
  void (*previous_)(int) = SIG_DFL;
};

// Interrupts the camera's Grab() once Ctrl-C is pressed: a ros2: source would otherwise wait for
// a silent publisher up to its timeout before the loop sees the flag. (A signal handler may not
// call into the camera; this thread may.)
class InterruptOnSigint {
 public:
  explicit InterruptOnSigint(Camera& camera)
      : thread_([this, &camera] {
          while (!done_.load()) {
            if (g_interrupted.load()) {
              camera.Interrupt();
              return;
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
          }
        }) {}
  ~InterruptOnSigint() {
    done_.store(true);
    thread_.join();
  }
  InterruptOnSigint(const InterruptOnSigint&) = delete;
  InterruptOnSigint& operator=(const InterruptOnSigint&) = delete;

 private:
  std::atomic<bool> done_{false};
  std::thread thread_;
};

struct RunOptions {
  std::string camera;
  long long frames = 0;
  std::string config;
  std::string calibration;
  std::string alternate_calibration;
  std::string controller;
  std::string out;
  int png_every = 0;
  int ply_every = 0;
  std::optional<double> fps;  // unset: the config's controller.frame_rate_hz
  bool print_config = false;
  CameraSourceOptions source;
  // --ros2: publish every frame as ROS 2 topics (docs/ros2.md).
  bool ros2 = false;
  std::string ros2_namespace = "/tofcam";
  int ros2_domain = 0;
  std::string ros2_frame_id = "tofcam_optical_frame";
  bool ros2_reliable = false;
  int ros2_wait_subscribers = 0;
  double ros2_wait_s = 10.0;
};

// Milli-units for the status line; "-" for NaN.
std::string Milli(double value_m) {
  if (!std::isfinite(value_m)) return "-";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1f mm", value_m * 1e3);
  return buffer;
}

std::string FrameName(std::uint64_t index, const char* suffix) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "frame_%06llu%s", static_cast<unsigned long long>(index),
                suffix);
  return buffer;
}

// Frames per second over `intervals` frame intervals spanning `seconds` of camera time.
std::string CameraRate(long long intervals, double seconds) {
  if (intervals < 1 || !(seconds > 0.0)) return "-";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1f/s", static_cast<double>(intervals) / seconds);
  return buffer;
}

nlohmann::json Real(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

PipelineOptions ResolveOptions(const RunOptions& o, std::set<std::string>* given_keys) {
  PipelineOptions options =
      o.config.empty() ? PipelineOptions{} : LoadPipelineConfig(o.config, given_keys);
  if (!o.calibration.empty()) options.calibration_file = o.calibration;
  if (!o.alternate_calibration.empty()) {
    options.alternate_calibration_file = o.alternate_calibration;
  }
  if (o.fps) {
    if (!std::isfinite(*o.fps) || *o.fps < 0.0) {
      throw Error(ErrorCode::kInvalidArgument,
                  "--fps " + std::to_string(*o.fps) + ": expected a frame rate >= 0 Hz");
    }
    options.controller.frame_rate_hz = *o.fps;
    if (given_keys != nullptr) given_keys->insert("controller.frame_rate_hz");
  }
  if (!o.controller.empty()) {
    if (o.controller == "none") {
      options.controller_enabled = false;
    } else {
      options.controller_enabled = true;
      options.controller.kind = ParseControllerKind(o.controller);
    }
  }
  options.Validate();
  return options;
}

// What the camera source knows about its own noise: an importer's figure, or for a simulator
// (and recordings of one) the ground-truth σ of its first frame.
std::pair<std::optional<double>, std::string> SourceNoiseScale(const Camera& camera,
                                                               const std::optional<Frame>& first) {
  if (const auto* imported = dynamic_cast<const ImportedCamera*>(&camera)) {
    if (imported->delta_l_scale()) {
      return {imported->delta_l_scale(), "the importer (" + imported->delta_l_scale_note() + ")"};
    }
  }
  if (first && first->truth) {
    if (const std::optional<double> scale = GroundTruthNoiseScale(ConvertToMetric(*first))) {
      return {scale, "the source's ground-truth noise (first frame)"};
    }
  }
  return {std::nullopt, {}};
}

#ifdef TOFCAM_WITH_ROS2
// Remote commands (docs/ros2.md): I_A for the controller; a register for the controller (the
// fixed one holds it) or, when not controlling, for the camera. Takes effect from the next
// frame; a refused command is a warning, not the end of the run. Returns the number applied.
int ApplyRemoteCommands(const ros2::Ros2Commands& commands, bool controlling,
                        PipelineResult& result, Pipeline& pipeline, Camera& camera) {
  int applied = 0;
  if (commands.target_intensity) {
    try {
      if (!controlling) throw Error(ErrorCode::kUnsupported, "not controlling");
      pipeline.SetTargetIntensity(*commands.target_intensity, result.next_integration_register);
      std::fprintf(stderr, "run: remote: I_A %.6g applied\n", *commands.target_intensity);
      ++applied;
    } catch (const Error& e) {
      std::fprintf(stderr, "run: warning: remote I_A %.6g refused: %s\n",
                   *commands.target_intensity, e.what());
    }
  }
  if (commands.integration_register) {
    try {
      int reg = *commands.integration_register;
      if (controlling) reg = pipeline.SetControllerRegister(reg);
      camera.SetIntegrationTimeRegister(reg);
      result.next_integration_register = reg;
      std::fprintf(stderr, "run: remote: integration register %d applied\n", reg);
      ++applied;
    } catch (const Error& e) {
      std::fprintf(stderr, "run: warning: remote integration register %d refused: %s\n",
                   *commands.integration_register, e.what());
    }
  }
  return applied;
}
#endif

void RunRun(const RunOptions& o) {
  std::set<std::string> given_keys;
  PipelineOptions options = ResolveOptions(o, &given_keys);
  if (o.print_config) {
    std::fputs(PipelineConfigToYaml(options, &given_keys).c_str(), stdout);
    return;
  }
  if (o.camera.empty()) throw Error(ErrorCode::kInvalidArgument, "--camera is required");
  if (o.out.empty()) throw Error(ErrorCode::kInvalidArgument, "--out is required");
  if (o.frames <= 0) {
    // 0 is also the value when --frames was not given.
    throw Error(ErrorCode::kInvalidArgument,
                "--frames " + std::to_string(o.frames) + " must be >= 1 (--frames N is required)");
  }
  if (o.png_every < 0 || o.ply_every < 0) {
    throw Error(ErrorCode::kInvalidArgument, "--png-every and --ply-every must be >= 0");
  }

  const fs::path out(o.out);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) {
    throw Error(ErrorCode::kIo, "--out " + o.out + ": cannot create the directory" +
                                    (ec ? ": " + ec.message() : std::string()));
  }
  const fs::path csv_path = out / "frames.csv";
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> csv(std::fopen(csv_path.c_str(), "w"),
                                                      &std::fclose);
  if (!csv) {
    throw Error(ErrorCode::kIo, "cannot write " + csv_path.string() + ": " + std::strerror(errno));
  }

  CameraSourceOptions source = o.source;
  source.ros2_domain = o.ros2_domain;
#ifdef TOFCAM_WITH_ROS2
  if (o.ros2 && o.camera.rfind("ros2:", 0) == 0) {
    // Subscribing to what this run publishes would feed its output back as its input.
    const ros2::Ros2CameraOptions in = ros2::ParseRos2CameraSpec(o.camera.substr(5), o.ros2_domain);
    const std::string out_prefix = (o.ros2_namespace == "/" ? "" : o.ros2_namespace) + "/";
    for (const std::string& topic :
         {in.depth_topic, in.amplitude_topic, in.intensity_topic, in.camera_info_topic}) {
      const std::string resolved = topic.empty() ? "" : ros2::ResolveTopic(in.name_space, topic);
      if (in.domain_id == o.ros2_domain && resolved.rfind(out_prefix, 0) == 0) {
        throw Error(ErrorCode::kInvalidArgument,
                    "--camera " + o.camera + " reads " + resolved + ", inside --ros2-namespace " +
                        o.ros2_namespace + " that this run publishes: use another namespace");
      }
    }
  }
#endif
  std::unique_ptr<Camera> camera = OpenCamera(o.camera, source);
  LoadPipelineCalibration(options, camera->Info());
  // Camera-specific values the configuration left at their defaults come from measurements of
  // this camera (docs/pipeline.md): the calibration file, else what the source knows.
  MeasuredDefaults from = ApplyMeasuredDefaults(options, given_keys);
  bool controlling = options.controller_enabled;
  if (controlling) {
    try {
      camera->SetIntegrationTimeRegister(std::clamp(options.controller.bias_register,
                                                    camera->Info().min_integration_register,
                                                    camera->Info().max_integration_register));
    } catch (const Error& e) {
      if (e.code() != ErrorCode::kUnsupported) throw;
      std::fprintf(stderr, "run: the camera's integration time is fixed (%s); not controlling\n",
                   e.what());
      controlling = false;
    }
  }
  // A simulator's truth is read from the first frame, which is then processed first below.
  std::optional<Frame> first;
  const bool scale_measured =
      given_keys.count("accuracy.scale") > 0 || (options.calibration && options.calibration->noise);
  if (!scale_measured) {
    if (camera->Info().has_ground_truth) first = camera->Grab();
    const auto [source_scale, source_note] = SourceNoiseScale(*camera, first);
    from = ApplyMeasuredDefaults(options, given_keys, source_scale, source_note);
  }
  std::fprintf(stderr, "run: dL scale %.4g from %s\n", options.accuracy.scale,
               from.delta_l_scale.c_str());
  if (options.scattering_enabled) {
    std::string lobes;
    for (const ScatteringLobe& l : options.scattering.lobes) {
      if (l.weight <= 0.0) continue;
      char text[64];
      std::snprintf(text, sizeof text, "%s%.3g at %.3g px", lobes.empty() ? "" : ", ", l.weight,
                    l.sigma_px);
      lobes += text;
    }
    std::fprintf(stderr, "run: scattering compensation on (%s) from %s\n",
                 lobes.empty() ? "no lobes" : lobes.c_str(), from.scattering.c_str());
  }
  Pipeline pipeline(options, camera->Info());
  if (controlling && pipeline.ControllerName().empty()) {
    std::fprintf(stderr, "run: no exposure control (the source's integration time is fixed)\n");
    controlling = false;
  } else if (controlling) {
    const ControllerOptions& c = pipeline.options().controller;
    char vp[64];
    if (c.gain_register_per_intensity > 0.0) {
      std::snprintf(vp, sizeof vp, "%.3g", c.gain_register_per_intensity);
    } else {
      std::snprintf(vp, sizeof vp, "scheduled (loop gain %.2g)", c.loop_gain);
    }
    std::fprintf(stderr,
                 "run: controller %s, I_A %.0f, V_p %s, c_0 %d from %s; registers %d..%d "
                 "(%.0f frames/s)\n",
                 std::string(pipeline.ControllerName()).c_str(), c.target_intensity, vp,
                 c.bias_register, from.controller.c_str(), c.min_register, c.max_register,
                 c.frame_rate_hz);
  }

#ifdef TOFCAM_WITH_ROS2
  std::unique_ptr<ros2::Ros2Publisher> ros2;
  if (o.ros2) {
    ros2::Ros2Options ro;
    ro.domain_id = o.ros2_domain;
    ro.name_space = o.ros2_namespace;
    ro.frame_id = o.ros2_frame_id;
    ro.reliable = o.ros2_reliable;
    if (o.ros2_reliable) ro.history_depth = 10;  // the ROS 2 default profile
    ros2 = std::make_unique<ros2::Ros2Publisher>(ro, camera->Info());
    std::fprintf(stderr,
                 "run: publishing ROS 2 topics %s/{points,depth,...} in DDS domain %d (%s)\n",
                 o.ros2_namespace == "/" ? "" : o.ros2_namespace.c_str(), o.ros2_domain,
                 o.ros2_reliable ? "reliable" : "best effort");
    if (o.ros2_wait_subscribers > 0 &&
        !ros2->WaitForSubscribers(o.ros2_wait_subscribers, o.ros2_wait_s)) {
      throw Error(ErrorCode::kNotFound,
                  "--ros2-wait-subscribers " + std::to_string(o.ros2_wait_subscribers) + ": only " +
                      std::to_string(ros2->MatchedSubscribers()) + " subscriber(s) of " +
                      ros2::DdsTopicName(o.ros2_namespace, "*") + " in DDS domain " +
                      std::to_string(o.ros2_domain) + " after " + std::to_string(o.ros2_wait_s) +
                      " s");
    }
  }
  double ros2_publish_s = 0.0;
  int ros2_commands = 0;
#else
  if (o.ros2) {
    throw Error(ErrorCode::kUnsupported,
                "--ros2: this tofcam was built without ROS 2 support "
                "(TOFCAM_BUILD_ROS2=OFF or Cyclone DDS missing)");
  }
#endif

  std::fprintf(csv.get(), "frame,%s,elapsed_s\n", FrameStatsCsvHeader().c_str());
  SigintGuard sigint;
  RunStatsAccumulator accumulator;
  PipelineResult result;
  const Clock::time_point start = Clock::now();
  Clock::time_point last_status = start;
  Clock::time_point last_flush = start;
  long long status_frames = 0;
  long long done = 0;
  // Camera time (the frames' timestamps): the frame rate the camera delivered, as opposed to the
  // processing rate (frames per wall-clock second).
  std::int64_t first_timestamp_ns = 0, last_timestamp_ns = 0, status_timestamp_ns = 0;
  bool end_of_stream = false;

  const InterruptOnSigint interrupt_on_sigint(*camera);
  while (done < o.frames && !g_interrupted.load()) {
    std::optional<Frame> frame = done == 0 && first ? std::move(first) : camera->Grab();
    if (!frame) {
      end_of_stream = !g_interrupted.load();  // Ctrl-C interrupts a waiting Grab() too
      break;
    }
    if (done == 0) first_timestamp_ns = status_timestamp_ns = frame->info.timestamp_ns;
    last_timestamp_ns = frame->info.timestamp_ns;
    pipeline.Process(*frame, result);
    if (controlling) camera->SetIntegrationTimeRegister(result.next_integration_register);
    if (result.next_modulation_frequency_hz != frame->info.modulation_frequency_hz) {
      camera->SetModulationFrequencyHz(result.next_modulation_frequency_hz);  // dual frequency
    }
#ifdef TOFCAM_WITH_ROS2
    if (ros2) {
      const Clock::time_point publish_start = Clock::now();
      ros2::Ros2ControllerState state;
      state.name = controlling ? std::string(pipeline.ControllerName()) : std::string();
      state.target_intensity = pipeline.options().controller.target_intensity;
      state.next_integration_register = result.next_integration_register;
      ros2->Publish(result, pipeline.RenderFiltered(result), state);
      ros2_publish_s += std::chrono::duration<double>(Clock::now() - publish_start).count();
      ros2_commands +=
          ApplyRemoteCommands(ros2->TakeCommands(), controlling, result, pipeline, *camera);
    }
#endif
    const FrameStats& s = result.stats;
    accumulator.Add(s);
    const Clock::time_point now = Clock::now();
    const double elapsed_s = std::chrono::duration<double>(now - start).count();
    std::fprintf(csv.get(), "%lld,%s,%.6f\n", done, FrameStatsCsvRow(s).c_str(), elapsed_s);

    if (o.png_every > 0 && done % o.png_every == 0) {
      WritePngRgb8(out / FrameName(done, "_raw.png"), pipeline.RenderRaw(result));
      WritePngRgb8(out / FrameName(done, "_filtered.png"), pipeline.RenderFiltered(result));
    }
    if (o.ply_every > 0 && done % o.ply_every == 0 && !result.cloud.empty()) {
      WritePly(out / FrameName(done, ".ply"), result.cloud, PlyFormat::kBinary,
               /*only_valid=*/true);
    }
    ++done;
    ++status_frames;

    if (now - last_flush >= std::chrono::milliseconds(500)) {
      std::fflush(csv.get());
      last_flush = now;
    }
    const double since_status = std::chrono::duration<double>(now - last_status).count();
    if (since_status >= 1.0 || done == o.frames) {
      const double camera_s = static_cast<double>(last_timestamp_ns - status_timestamp_ns) * 1e-9;
      std::fprintf(stderr,
                   "run: frame %lld/%lld  %.1f frames/s (camera %s)  register %d (%.2f ms)  "
                   "intensity %.0f  valid %.1f%%  mean dL %s  RMSE %s\n",
                   done, o.frames, status_frames / std::max(since_status, 1e-9),
                   CameraRate(status_frames - 1, camera_s).c_str(), s.integration_time_register,
                   s.integration_time_us * 1e-3, s.mean_intensity, s.valid_fraction * 100.0,
                   Milli(s.mean_delta_l_m).c_str(), s.has_truth ? Milli(s.rmse_m).c_str() : "n/a");
      last_status = now;
      status_frames = 0;
      status_timestamp_ns = last_timestamp_ns;
    }
  }
  if (std::fflush(csv.get()) != 0) {
    throw Error(ErrorCode::kIo, "cannot write " + csv_path.string() + ": " + std::strerror(errno));
  }
  const double elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();
  const RunSummary summary = accumulator.Summary();

  nlohmann::json json;
  json["camera"] = o.camera;
  json["camera_model"] = camera->Info().model;
  json["controller"] = controlling ? std::string(pipeline.ControllerName()) : "none";
  json["calibrated"] = options.calibration.has_value();
  json["delta_l_scale"] = options.accuracy.scale;
  json["delta_l_scale_from"] = from.delta_l_scale;
  json["controller_setpoint"] = {
      {"target_intensity", options.controller.target_intensity},
      {"gain_register_per_intensity", options.controller.gain_register_per_intensity},
      {"bias_register", options.controller.bias_register},
      {"from", from.controller}};
  json["frames"] = summary.frames;
  json["mean_valid_fraction"] = Real(summary.mean_valid_fraction);
  json["mean_delta_l_m"] = Real(summary.mean_delta_l_m);
  json["mean_intensity"] = Real(summary.mean_intensity);
  json["has_truth"] = summary.has_truth;
  json["rmse_m"] = Real(summary.rmse_m);
  json["footprint_rmse_m"] = Real(summary.footprint_rmse_m);
  json["bad_removed_fraction"] = Real(summary.bad_removed_fraction);
  json["good_kept_fraction"] = Real(summary.good_kept_fraction);
  json["bad_pixels"] = summary.bad_pixels;
  json["good_pixels"] = summary.good_pixels;
  json["bad_error_m"] = options.stats.bad_error_m;
  json["elapsed_s"] = elapsed_s;
  json["mean_frames_per_s"] = Real(elapsed_s > 0 ? summary.frames / elapsed_s : NAN);
  // Frames per second of camera time (timestamps), what the integration time allowed.
  const double camera_s = static_cast<double>(last_timestamp_ns - first_timestamp_ns) * 1e-9;
  json["camera_frames_per_s"] =
      Real(summary.frames > 1 && camera_s > 0 ? (summary.frames - 1) / camera_s : NAN);
  json["frame_rate_limit_hz"] = pipeline.options().controller.frame_rate_hz;
  json["interrupted"] = g_interrupted.load();
  json["end_of_stream"] = end_of_stream;
#ifdef TOFCAM_WITH_ROS2
  if (const auto* ros2_camera = dynamic_cast<const ros2::Ros2Camera*>(camera.get())) {
    // Malformed or unpaired samples the ROS 2 source skipped (never processed).
    json["source_skipped_samples"] = ros2_camera->skipped();
    if (ros2_camera->skipped() > 0) {
      json["source_last_skip"] = ros2_camera->last_skip();
      std::fprintf(stderr, "run: warning: the ROS 2 source skipped %llu sample(s); last: %s\n",
                   static_cast<unsigned long long>(ros2_camera->skipped()),
                   ros2_camera->last_skip().c_str());
    }
  }
  if (ros2) {
    ros2->Flush(2.0);
    // Time spent converting and handing each frame to DDS (false colour included), ms.
    json["ros2_published_frames"] = ros2->published_frames();
    json["ros2_commands_applied"] = ros2_commands;
    json["ros2_publish_ms_per_frame"] =
        Real(summary.frames > 0 ? 1e3 * ros2_publish_s / summary.frames : NAN);
  }
#endif
  WriteFileAtomically(out / "summary.json", json.dump(2) + "\n");

  std::printf("run: %llu frames in %.2f s (%.1f frames/s)%s\n",
              static_cast<unsigned long long>(summary.frames), elapsed_s,
              elapsed_s > 0 ? summary.frames / elapsed_s : 0.0,
              g_interrupted.load() ? ", interrupted" : (end_of_stream ? ", end of stream" : ""));
  std::printf("run: mean valid %.1f%%, mean dL %s", summary.mean_valid_fraction * 100.0,
              Milli(summary.mean_delta_l_m).c_str());
  if (summary.has_truth) {
    std::printf(", RMSE of kept pixels %s, bad pixels removed %.1f%%, good pixels kept %.1f%%",
                Milli(summary.rmse_m).c_str(), summary.bad_removed_fraction * 100.0,
                summary.good_kept_fraction * 100.0);
  }
  std::printf("\nrun: wrote %s and %s\n", csv_path.c_str(), (out / "summary.json").c_str());
}

void SetupRunCommand(CLI::App& app) {
  auto o = std::make_shared<RunOptions>();
  CLI::App* sub = app.add_subcommand(
      "run", "Camera -> pipeline -> integration-time controller in a loop (Ctrl-C stops)");
  sub->add_option("--camera", o->camera, "Frame source: " + CameraSourceHelp());
  sub->add_option("--frames", o->frames, "Frames to process (>= 1)");
  sub->add_option("--config", o->config, "Pipeline configuration (YAML; see --print-config)");
  sub->add_option("--calibration", o->calibration,
                  "Calibration file (tofcam calibrate); overrides the config's");
  sub->add_option("--alternate-calibration", o->alternate_calibration,
                  "Calibration made at frame_pair's alternate modulation frequency (dual-frequency "
                  "runs with a calibration need one); overrides the config's");
  sub->add_option(
      "--controller", o->controller,
      "may-proportional, may-incremental, vendor-histogram, fixed, model-based or none; "
      "overrides the config's");
  sub->add_option("--out", o->out, "Output directory (frames.csv, summary.json, PNG, PLY)");
  sub->add_option("--png-every", o->png_every,
                  "Write false-colour PNGs (raw and filtered) of every K-th frame; 0 = none")
      ->capture_default_str();
  sub->add_option("--ply-every", o->ply_every,
                  "Write the point cloud (valid points, binary PLY) of every K-th frame; 0 = none")
      ->capture_default_str();
  sub->add_option("--seed", o->source.seed, "Simulator noise seed")
      ->check(kNonNegative)
      ->capture_default_str();
  sub->add_option("--camera-model", o->source.camera_model, "Simulator camera model");
  sub->add_flag("--real-time", o->source.real_time, "Throttle to the camera's frame rate");
  sub->add_flag("--loop", o->source.loop, "Loop finite sources (playback, imports)");
  sub->add_option("--fps", o->fps,
                  "Frame rate the integration time must leave, Hz (0 = the camera's maximum, "
                  "SR-2: 30); overrides the config's controller.frame_rate_hz");
  sub->add_flag("--print-config", o->print_config,
                "Print every pipeline option (defaults, or --config's values) as YAML and exit");
  sub->add_flag("--ros2", o->ros2,
                "Publish every frame as ROS 2 topics over DDS (points, depth, depth/mm, amplitude, "
                "intensity, false_color, camera_info, diagnostics; docs/ros2.md)");
  sub->add_option("--ros2-namespace", o->ros2_namespace, "ROS namespace of the topics")
      ->capture_default_str();
  sub->add_option("--ros2-domain", o->ros2_domain,
                  "DDS domain (ROS_DOMAIN_ID), 0..232, of --ros2 and of a ros2: camera")
      ->check(CLI::Range(0, 232))
      ->capture_default_str();
  sub->add_option("--ros2-frame-id", o->ros2_frame_id,
                  "header.frame_id: the camera's optical frame (REP 103)")
      ->capture_default_str();
  sub->add_flag(
      "--ros2-reliable", o->ros2_reliable,
      "Reliable QoS, keep last 10 (default: best effort, keep last 5, as sensor drivers)");
  sub->add_option("--ros2-wait-subscribers", o->ros2_wait_subscribers,
                  "Before the first frame, wait until this many subscribers matched one of the "
                  "topics (error after --ros2-wait-s); 0 = do not wait")
      ->capture_default_str();
  sub->add_option("--ros2-wait-s", o->ros2_wait_s, "Timeout of --ros2-wait-subscribers, s")
      ->capture_default_str();
  sub->callback([o] { RunRun(*o); });
}

TOFCAM_REGISTER_COMMAND("run", SetupRunCommand);

}  // namespace
}  // namespace tofcam::cli

// `tofcam view`: the live viewer (issue 17, docs/viewer.md). Runs the pipeline on any camera
// source at camera rate and serves a page on loopback that shows and steers it.
#include <atomic>
#include <csignal>
#include <cstdio>
#include <memory>
#include <optional>
#include <set>
#include <string>

#include "camera_source.h"
#include "commands.h"
#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/core/error.h"
#include "tofcam/io/pipeline_config.h"
#include "tofcam/pipeline/metric_conversion.h"
#include "viewer_server.h"

namespace tofcam::cli {
namespace {

struct ViewCommandOptions {
  std::string camera;
  viewer::ViewerOptions server;
  std::string config;
  std::string calibration;
  std::string controller;
  bool no_real_time = false;
  CameraSourceOptions source;
};

std::atomic<bool> g_stop{false};
extern "C" void OnStopSignal(int /*signal*/) { g_stop.store(true); }

void RunView(const ViewCommandOptions& o) {
  std::set<std::string> given_keys;
  PipelineOptions options =
      o.config.empty() ? PipelineOptions{} : LoadPipelineConfig(o.config, &given_keys);
  if (!o.calibration.empty()) options.calibration_file = o.calibration;
  if (!o.controller.empty()) {
    options.controller_enabled = o.controller != "none";
    if (options.controller_enabled) options.controller.kind = ParseControllerKind(o.controller);
  }
  CameraSourceOptions source = o.source;
  source.real_time = !o.no_real_time;
  const viewer::CameraOpener opener = [source](const std::string& spec) {
    return OpenCamera(spec, source);
  };
  {
    // Camera-specific defaults as `tofcam run` takes them: the calibration file, else what the
    // source knows (a simulator's ground-truth noise).
    std::unique_ptr<Camera> probe = OpenCamera(o.camera, o.source);
    LoadPipelineCalibration(options, probe->Info());
    (void)ApplyMeasuredDefaults(options, given_keys);
    if (!given_keys.count("accuracy.scale") &&
        !(options.calibration && options.calibration->noise) && probe->Info().has_ground_truth) {
      if (const std::optional<Frame> first = probe->Grab()) {
        if (const auto scale = GroundTruthNoiseScale(ConvertToMetric(*first))) {
          options.accuracy.scale = *scale;
        }
      }
    }
  }
  viewer::ViewerOptions server = o.server;
  server.camera_spec = o.camera;
  viewer::ViewerServer view(server, options, opener);
  g_stop.store(false);
  const auto previous_int = std::signal(SIGINT, OnStopSignal);
  const auto previous_term = std::signal(SIGTERM, OnStopSignal);
  view.Start();
  std::fprintf(stderr, "view: serving http://%s:%d/ for %s (Ctrl-C stops)\n",
               server.bind_address.c_str(), view.port(), o.camera.c_str());
  std::fflush(stderr);
  while (!g_stop.load() && !view.WaitFor(0.1)) {
  }
  view.Stop();
  std::signal(SIGINT, previous_int == SIG_ERR ? SIG_DFL : previous_int);
  std::signal(SIGTERM, previous_term == SIG_ERR ? SIG_DFL : previous_term);
  const viewer::ViewerStatus s = view.Status();
  std::printf(
      "view: %lld frames, %lld sent to browsers, %lld dropped for slow clients, %.2f ms CPU per "
      "frame (camera loop + server), valid %.1f %% in the last frame\n",
      s.frames, s.served, s.dropped, s.cpu_ms_per_frame, 100.0 * s.valid_fraction);
}

void SetupViewCommand(CLI::App& app) {
  auto o = std::make_shared<ViewCommandOptions>();
  CLI::App* sub = app.add_subcommand(
      "view",
      "Live viewer in the browser: see and steer the camera while it runs (docs/viewer.md)");
  sub->add_option("--camera", o->camera, "Camera source; " + CameraSourceHelp())->required();
  sub->add_option("--port", o->server.port, "TCP port (0 = any free port, printed)")
      ->capture_default_str();
  sub->add_option("--bind", o->server.bind_address,
                  "Address to listen on; loopback by default (others can then steer the camera)")
      ->capture_default_str();
  sub->add_option("--config", o->config, "Pipeline configuration (YAML, as tofcam run)");
  sub->add_option("--calibration", o->calibration, "Calibration file; overrides the config's");
  sub->add_option("--controller", o->controller,
                  "may-proportional, may-incremental, vendor-histogram, fixed, model-based or "
                  "none; overrides the config's");
  sub->add_option("--frames", o->server.max_frames, "Stop after N frames (0 = until Ctrl-C)")
      ->capture_default_str();
  sub->add_option("--record-dir", o->server.record_dir, "Where recordings started on the page go")
      ->capture_default_str();
  sub->add_flag("--loop", o->source.loop, "Playback: start again at the end of the recording");
  sub->add_flag("--no-real-time", o->no_real_time,
                "Run the simulator or a playback as fast as possible instead of at camera rate");
  sub->add_option("--seed", o->source.seed, "Simulator noise seed")
      ->check(kNonNegative)
      ->capture_default_str();
  AddRos2DomainOption(sub, o->source.ros2_domain);
  sub->add_option("--camera-model", o->source.camera_model,
                  "Simulator camera model (name or YAML file)");
  sub->callback([o] { RunView(*o); });
}

}  // namespace

TOFCAM_REGISTER_COMMAND("view", SetupViewCommand);

}  // namespace tofcam::cli

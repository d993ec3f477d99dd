// `tofcam record`: grabs frames from any camera source into a recording (HDF5).
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>

#include "camera_source.h"
#include "commands.h"
#include "tofcam/core/error.h"
#include "tofcam/io/recording.h"

namespace tofcam::cli {
namespace {

struct RecordOptions {
  std::string camera;
  std::string out;
  long long frames = 0;
  int compression_level = 4;
  std::string calibration_id;
  bool no_flush = false;
  long long progress_every = 0;
  CameraSourceOptions source;
};

void RunRecord(const RecordOptions& o) {
  constexpr long long kMaxFrames = 1LL << 24;  // the reader's limit too
  if (o.frames < 1 || o.frames > kMaxFrames) {
    throw Error(ErrorCode::kInvalidArgument, "--frames " + std::to_string(o.frames) +
                                                 " outside 1.." + std::to_string(kMaxFrames));
  }
  if (o.progress_every < 0) {
    throw Error(ErrorCode::kInvalidArgument, "--progress-every must be >= 0");
  }
  std::unique_ptr<Camera> camera = OpenCamera(o.camera, o.source);
  RecordingOptions options;
  options.compression_level = o.compression_level;
  options.calibration_id = o.calibration_id;
  options.flush_each_frame = !o.no_flush;
  RecordingWriter writer(o.out, camera->Info(), options);
  const auto start = std::chrono::steady_clock::now();
  auto last_report = start;
  long long n = 0;
  for (; n < o.frames; ++n) {
    std::optional<Frame> frame = camera->Grab();
    if (!frame) {
      std::fprintf(stderr, "record: the source ended after %lld frames\n", n);
      break;
    }
    writer.Append(*frame);
    const auto now = std::chrono::steady_clock::now();
    const bool due = o.progress_every > 0 ? (n + 1) % o.progress_every == 0
                                          : now - last_report >= std::chrono::seconds(1);
    if (due) {
      last_report = now;
      std::fprintf(stderr, "record: %lld / %lld frames\n", n + 1, o.frames);
    }
  }
  writer.Close();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::fprintf(stderr, "record: wrote %lld frames to %s in %.2f s (%.1f frames/s)\n", n,
               o.out.c_str(), seconds, seconds > 0 ? n / seconds : 0.0);
}

void SetupRecordCommand(CLI::App& app) {
  auto o = std::make_shared<RecordOptions>();
  CLI::App* sub = app.add_subcommand("record", "Record frames from a camera source to HDF5");
  sub->add_option("--camera", o->camera, "Camera source: " + CameraSourceHelp())->required();
  sub->add_option("--frames", o->frames, "Number of frames to record (1..2^24)")->required();
  sub->add_option("--out", o->out, "Output recording (.h5), overwritten")->required();
  sub->add_option("--compression", o->compression_level, "Deflate level 0..9")
      ->capture_default_str();
  sub->add_option("--calibration-id", o->calibration_id,
                  "Identity of the calibration in use, stored in the file");
  sub->add_flag("--no-flush", o->no_flush,
                "Do not flush after every frame (faster; a crash may lose all frames)");
  sub->add_option("--progress-every", o->progress_every,
                  "Report progress every N frames, after the frame is on disk (0 = every second)")
      ->capture_default_str();
  sub->add_option("--seed", o->source.seed, "Simulator noise seed")
      ->check(kNonNegative)
      ->capture_default_str();
  AddRos2DomainOption(sub, o->source.ros2_domain);
  sub->add_flag("--real-time", o->source.real_time, "Throttle the source to its frame rate");
  sub->add_flag("--loop", o->source.loop, "Loop finite sources (playback, imports)");
  sub->add_option("--integration-time-register", o->source.integration_time_register,
                  "Integration-time register (0 = source default)");
  sub->add_option("--camera-model", o->source.camera_model, "Simulator camera model");
  sub->callback([o] { RunRecord(*o); });
}

TOFCAM_REGISTER_COMMAND("record", SetupRecordCommand);

}  // namespace
}  // namespace tofcam::cli

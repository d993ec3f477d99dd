// `tofcam export`: writes every frame of a recording (or any camera source) as PLY, PCD, PNG or
// CSV files, one (set of) file(s) per frame.
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "camera_source.h"
#include "commands.h"
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/io/cloud_io.h"
#include "tofcam/io/png.h"
#include "tofcam/io/recording.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam::cli {
namespace {

namespace fs = std::filesystem;

struct ExportOptions {
  std::string in;
  std::string camera;
  std::string out;
  std::string format;
  long long first = 0;
  long long count = -1;
  bool only_valid = false;
  CameraSourceOptions source;
};

std::string FrameStem(std::size_t index) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "frame_%06zu", index);
  return buffer;
}

void WriteCsv(const fs::path& path, const Frame& frame) {
  const double l = UnambiguousRangeM(frame.info.modulation_frequency_hz);
  std::string text = "row,col,distance_register,distance_m,amplitude,intensity,flags\n";
  text.reserve(text.size() + frame.distance.size() * 40);
  char line[128];
  for (int r = 0; r < frame.height(); ++r) {
    for (int c = 0; c < frame.width(); ++c) {
      const std::uint16_t flags =
          frame.source_flags.empty() ? std::uint16_t{0} : frame.source_flags(r, c).bits();
      const int n = std::snprintf(
          line, sizeof line, "%d,%d,%u,%.6f,%u,%u,%u\n", r, c, unsigned{frame.distance(r, c)},
          frame.distance(r, c) * l / kDistanceRegisterSpan, unsigned{frame.amplitude(r, c)},
          unsigned{frame.intensity(r, c)}, unsigned{flags});
      text.append(line, static_cast<std::size_t>(n));
    }
  }
  WriteFileAtomically(path, text);
}

void RunExport(const ExportOptions& o) {
  if (o.format != "ply" && o.format != "pcd" && o.format != "png" && o.format != "csv") {
    throw Error(ErrorCode::kInvalidArgument,
                "--format '" + o.format + "': expected ply, pcd, png or csv");
  }
  if (o.in.empty() == o.camera.empty()) {
    throw Error(ErrorCode::kInvalidArgument, "give exactly one of --in FILE or --camera SPEC");
  }
  if (o.first < 0) throw Error(ErrorCode::kInvalidArgument, "--first must be >= 0");
  if (o.count < -1) {
    throw Error(ErrorCode::kInvalidArgument,
                "--count " + std::to_string(o.count) + ": expected -1 (all) or a count >= 0");
  }
  if (!o.camera.empty() && o.count == -1 && !CameraSourceEnds(o.camera)) {
    throw Error(ErrorCode::kInvalidArgument,
                "--camera '" + o.camera +
                    "' does not end by itself: give the number of frames with --count N");
  }
  std::unique_ptr<Camera> camera;
  if (!o.in.empty()) {
    auto playback = std::make_unique<PlaybackCamera>(o.in);
    if (static_cast<std::size_t>(o.first) >= playback->frame_count()) {
      throw Error(ErrorCode::kInvalidArgument,
                  "--first " + std::to_string(o.first) + ": the recording has " +
                      std::to_string(playback->frame_count()) + " frames");
    }
    playback->Seek(static_cast<std::size_t>(o.first));
    camera = std::move(playback);
  } else {
    camera = OpenCamera(o.camera, o.source);
    for (long long i = 0; i < o.first; ++i) {
      if (!camera->Grab()) throw Error(ErrorCode::kInvalidArgument, "--first beyond the source");
    }
  }
  std::error_code ec;
  fs::create_directories(o.out, ec);
  if (ec) throw Error(ErrorCode::kIo, o.out + ": cannot create directory (" + ec.message() + ")");
  const RayTable rays = MakeRayTable(camera->Info().intrinsics);
  std::size_t written = 0;
  for (std::size_t index = static_cast<std::size_t>(o.first);
       o.count < 0 || written < static_cast<std::size_t>(o.count); ++index) {
    std::optional<Frame> frame = camera->Grab();
    if (!frame) break;
    const fs::path stem = fs::path(o.out) / FrameStem(index);
    if (o.format == "csv") {
      WriteCsv(stem.string() + ".csv", *frame);
    } else if (o.format == "png") {
      WritePngGray16(stem.string() + "_distance.png", frame->distance);
      WritePngGray16(stem.string() + "_amplitude.png", frame->amplitude);
      if (frame->info.has_intensity) {
        WritePngGray16(stem.string() + "_intensity.png", frame->intensity);
      }
      if (!frame->source_flags.empty()) {
        Image<std::uint16_t> flags(frame->width(), frame->height());
        for (std::size_t i = 0; i < flags.size(); ++i) flags[i] = frame->source_flags[i].bits();
        WritePngGray16(stem.string() + "_flags.png", flags);
      }
    } else {
      const PointCloud cloud = MakePointCloud(ConvertToMetric(*frame), rays);
      if (o.format == "ply") {
        WritePly(stem.string() + ".ply", cloud, PlyFormat::kBinary, o.only_valid);
      } else {
        WritePcd(stem.string() + ".pcd", cloud, o.only_valid);
      }
    }
    ++written;
  }
  std::printf("export: wrote %zu frames as %s to %s\n", written, o.format.c_str(), o.out.c_str());
}

void SetupExportCommand(CLI::App& app) {
  auto o = std::make_shared<ExportOptions>();
  CLI::App* sub =
      app.add_subcommand("export", "Export a recording's frames to PLY, PCD, PNG or CSV files");
  sub->add_option("--in", o->in, "Recording (.h5) to export");
  sub->add_option("--camera", o->camera, "Or any camera source: " + CameraSourceHelp());
  AddRos2DomainOption(sub, o->source.ros2_domain);
  sub->add_option("--out", o->out, "Output directory (created)")->required();
  sub->add_option("--format", o->format,
                  "ply | pcd (point clouds, camera frame, m) | png (16-bit register images) | "
                  "csv (one row per pixel)")
      ->required();
  sub->add_option("--first", o->first, "First frame index")->capture_default_str();
  sub->add_option("--count", o->count, "Number of frames (-1 = all; a sim: source needs a count)")
      ->capture_default_str();
  sub->add_flag("--only-valid", o->only_valid, "PLY/PCD: write valid points only");
  sub->callback([o] { RunExport(*o); });
}

TOFCAM_REGISTER_COMMAND("export", SetupExportCommand);

}  // namespace
}  // namespace tofcam::cli

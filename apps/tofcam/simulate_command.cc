// `tofcam simulate`: renders frames of a simulator scene with ground truth, into a recording
// (HDF5, default) or into per-frame 16-bit PNGs plus float32 truth and JSON metadata.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "commands.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/io/png.h"
#include "tofcam/io/recording.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::cli {
namespace {

struct SimulateOptions {
  std::string scene = "pavilion";
  std::string camera_model;
  long long frames = 30;
  double integration_time_us = 0;  // 0 = the model's default register
  std::uint64_t seed = 1;
  std::string out;
  std::string format = "h5";
  int supersampling = 2;
  int threads = 1;
  double power_on_time_s = 600;
  std::optional<double> pan_deg;  // unset: the scene's own pan
  bool ideal = false;
  bool interreflection = false;
  int interreflection_samples = 4;
  bool planar_shortcut = false;
};

void WriteFloatImage(const std::filesystem::path& path, const Image<float>& image) {
  // Raw little-endian float32, row-major, width x height (see docs/simulator.md).
  std::string bytes(image.size() * sizeof(float), '\0');
  std::memcpy(bytes.data(), image.data(), bytes.size());
  WriteFileAtomically(path, bytes);
}

nlohmann::json FrameJson(const Frame& f, const std::string& scene, const std::string& stem) {
  nlohmann::json j;
  j["sequence"] = f.info.sequence;
  j["timestamp_ns"] = f.info.timestamp_ns;
  j["integration_time_register"] = f.info.integration_time_register;
  j["integration_time_us"] = f.info.integration_time_us;
  j["modulation_frequency_hz"] = f.info.modulation_frequency_hz;
  j["pan_angle_rad"] = f.info.pan_angle_rad;
  j["distance_offset_register"] = f.info.distance_offset_register;
  j["camera_model"] = f.info.camera_model;
  j["width"] = f.width();
  j["height"] = f.height();
  j["scene"] = scene;
  j["files"] = {{"distance", stem + "_distance.png"},
                {"amplitude", stem + "_amplitude.png"},
                {"intensity", stem + "_intensity.png"},
                {"truth_radial_distance_m", stem + "_truth_distance_m.f32"},
                {"truth_sigma_m", stem + "_truth_sigma_m.f32"},
                {"truth_footprint_near_m", stem + "_truth_footprint_near_m.f32"},
                {"truth_footprint_far_m", stem + "_truth_footprint_far_m.f32"},
                {"truth_causes", stem + "_truth_causes.png"}};
  return j;
}

void RunSimulate(const SimulateOptions& o) {
  if (o.frames < 1 || o.frames > (1LL << 24)) {
    throw Error(ErrorCode::kInvalidArgument,
                "--frames " + std::to_string(o.frames) + " outside 1..16777216");
  }
  if (o.out.empty()) throw Error(ErrorCode::kInvalidArgument, "--out is required");
  if (o.format != "h5" && o.format != "png") {
    throw Error(ErrorCode::kInvalidArgument, "--format '" + o.format + "' must be h5 or png");
  }
  const auto [scene_name, overrides] = sim::ParseSceneSpec(o.scene);
  sim::SimulatorOptions options =
      o.ideal ? sim::SimulatorOptions::Ideal() : sim::SimulatorOptions{};
  options.seed = o.seed;
  options.supersampling = o.supersampling;
  options.threads = o.threads;
  options.power_on_time_s = o.power_on_time_s;
  options.interreflection = o.interreflection;
  options.interreflection_samples = o.interreflection_samples;
  options.planar_shortcut = o.planar_shortcut;
  const sim::CameraModel model = sim::ResolveCameraModel(o.camera_model);
  sim::SimulatedCamera camera(sim::ResolveScene(scene_name, overrides), model, options);
  if (o.integration_time_us != 0) {
    const CameraInfo& info = camera.Info();
    if (!std::isfinite(o.integration_time_us)) {
      throw Error(ErrorCode::kInvalidArgument, "--integration-time-us must be finite");
    }
    const long reg = std::lround((o.integration_time_us - info.integration_time_base_us) /
                                 info.integration_time_step_us);
    if (reg < info.min_integration_register || reg > info.max_integration_register) {
      throw Error(ErrorCode::kInvalidArgument,
                  "--integration-time-us " + std::to_string(o.integration_time_us) + " outside " +
                      std::to_string(info.IntegrationTimeUs(info.min_integration_register)) + ".." +
                      std::to_string(info.IntegrationTimeUs(info.max_integration_register)) +
                      " us");
    }
    camera.SetIntegrationTimeRegister(static_cast<int>(reg));
  }
  if (o.pan_deg) camera.SetPanAngleRad(*o.pan_deg * kPi / 180);

  const std::filesystem::path out(o.out);
  std::unique_ptr<RecordingWriter> writer;
  if (o.format == "h5") {
    if (out.has_parent_path()) std::filesystem::create_directories(out.parent_path());
    writer = std::make_unique<RecordingWriter>(out, camera.Info());
  } else {
    std::error_code ec;
    std::filesystem::create_directories(out, ec);
    if (ec) throw Error(ErrorCode::kIo, o.out + ": cannot create directory: " + ec.message());
  }
  for (long long i = 0; i < o.frames; ++i) {
    const Frame f = *camera.Grab();
    if (writer) {
      writer->Append(f);
    } else {
      char stem[32];
      std::snprintf(stem, sizeof stem, "frame_%06lld", i);
      const std::filesystem::path base = out / stem;
      WritePngGray16(base.string() + "_distance.png", f.distance);
      WritePngGray16(base.string() + "_amplitude.png", f.amplitude);
      WritePngGray16(base.string() + "_intensity.png", f.intensity);
      WriteFloatImage(base.string() + "_truth_distance_m.f32", f.truth->radial_distance_m);
      WriteFloatImage(base.string() + "_truth_sigma_m.f32", f.truth->sigma_m);
      WriteFloatImage(base.string() + "_truth_footprint_near_m.f32", f.truth->footprint_near_m);
      WriteFloatImage(base.string() + "_truth_footprint_far_m.f32", f.truth->footprint_far_m);
      Image<std::uint16_t> causes(f.width(), f.height());
      for (std::size_t p = 0; p < causes.size(); ++p) causes[p] = f.truth->causes[p].bits();
      WritePngGray16(base.string() + "_truth_causes.png", causes);
      WriteFileAtomically(base.string() + ".json", FrameJson(f, o.scene, stem).dump(2) + "\n");
    }
    if ((i + 1) % 100 == 0) std::fprintf(stderr, "simulate: %lld / %lld frames\n", i + 1, o.frames);
  }
  if (writer) writer->Close();
  std::fprintf(stderr, "simulate: wrote %lld frames of '%s' to %s\n", o.frames, o.scene.c_str(),
               o.out.c_str());
}

void SetupSimulateCommand(CLI::App& app) {
  auto o = std::make_shared<SimulateOptions>();
  CLI::App* sub = app.add_subcommand("simulate", "Render simulator frames with ground truth");
  sub->add_option("--scene", o->scene,
                  "Built-in scene (wall, hand, pavilion, mirror, lamps, corridor, beyond-range, "
                  "demo, approach) or YAML file, optionally ?param=value&...")
      ->capture_default_str();
  sub->add_option("--camera-model", o->camera_model,
                  "sr2 (default), sr3000, sr4000, generic640x480 or a YAML file");
  sub->add_option("--frames", o->frames, "Number of frames")->capture_default_str();
  sub->add_option("--integration-time-us", o->integration_time_us,
                  "Integration time in us (rounded to a register step); 0 = model default")
      ->capture_default_str();
  sub->add_option("--seed", o->seed, "Noise seed")->check(kNonNegative)->capture_default_str();
  sub->add_option("--out", o->out, "Output: .h5 recording, or a directory with --format png")
      ->required();
  sub->add_option("--format", o->format, "h5 (recording) or png (per-frame files)")
      ->capture_default_str();
  sub->add_option("--supersampling", o->supersampling, "S x S rays per pixel (1..8)")
      ->capture_default_str();
  sub->add_option("--threads", o->threads, "Simulator threads (1..64)")->capture_default_str();
  sub->add_option("--power-on-time-s", o->power_on_time_s,
                  "Seconds the camera has been on (warm-up drift)")
      ->capture_default_str();
  sub->add_option("--pan-deg", o->pan_deg, "Fixed pan angle in degrees (overrides the scene)");
  sub->add_flag("--ideal", o->ideal, "Switch all effects off except the ideal 4-tap sensor");
  sub->add_flag("--interreflection", o->interreflection,
                "One-bounce diffuse inter-reflection (off by default: ~10 ms more per render)");
  sub->add_option("--interreflection-samples", o->interreflection_samples,
                  "Hemisphere samples per evaluated point (1..256)")
      ->capture_default_str();
  sub->add_flag(
      "--planar-shortcut", o->planar_shortcut,
      "Cast subsample rays in closed form on the plane their pixel centres hit (1.3-1.45x "
      "faster with a moving camera; frames equal to the exact ones up to rounding, "
      "docs/simulator.md)");
  sub->callback([o] { RunSimulate(*o); });
}

TOFCAM_REGISTER_COMMAND("simulate", SetupSimulateCommand);

}  // namespace
}  // namespace tofcam::cli

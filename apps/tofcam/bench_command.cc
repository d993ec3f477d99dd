// `tofcam bench`: per-stage and whole-pipeline speed on simulated frames at 160x124, 640x480 and
// 1024x1024, single- and two-threaded, each beside a memcpy moving the same number of bytes (the
// memory-bandwidth floor), plus simulator frames/s and the memory bandwidth. See
// docs/benchmarks.md.
//
// No stage has a threaded path of its own, so the 2-thread figure is two frames processed
// concurrently (each thread owns its inputs and outputs); it is reported as wall time per frame.
// Each stage figure is the median of 7 rounds of back-to-back batches of the stage and its
// floors (robust against other processes on a shared machine); simulator figures of 5 batches.
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

#include "bench_calibration.h"  // bench/: the inputs and calibration of the benchmarks
#include "bench_floor.h"
#include "commands.h"
#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/color/false_color.h"
#include "tofcam/control/integration_time_controller.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/filters/denoise.h"
#include "tofcam/filters/filter_set.h"
#include "tofcam/filters/frame_pair.h"
#include "tofcam/filters/neighbour_prediction.h"
#include "tofcam/filters/spatial_filter.h"
#include "tofcam/filters/temporal_filter.h"
#include "tofcam/filters/uncertainty.h"
#include "tofcam/io/recording.h"
#include "tofcam/optics/scattering.h"
#include "tofcam/pan/pan_view.h"
#include "tofcam/pipeline/metric_conversion.h"
#include "tofcam/pipeline/paper_chain.h"
#include "tofcam/pipeline/pipeline.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::cli {
namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

struct BenchOptions {
  bool json_output = false;
  int frames = 8;                // simulated frames per resolution, cycled through by every stage
  int threads = 0;               // 0 = both 1 and 2
  double min_time_s = 0.25;      // per figure (7 rounds of a stage batch and its floors)
  std::string export_peers_dir;  // write clouds + tofcam filter results for bench/peers
  bool skip_simulator = false;
  bool skip_recording = false;
  bool peers_only = false;  // only the peer export (no stage timings)
  // Only stages whose name contains one of these (empty: all), only these frame sizes
  // ("160x124", "640x480", "1024x1024"; empty: all).
  std::vector<std::string> stage_filters;
  std::vector<std::string> sizes;
};

// The simulated frames of one resolution and everything the stages need besides.
struct Input {
  std::string name;
  int width = 0;
  int height = 0;
  CameraInfo info;
  RayTable rays;
  OffsetCalibration calibration;
  OffsetCalibration calibration_eq1;  // the same offsets without the distance table
  std::vector<Frame> frames;
  // The same registers without ground truth: what a real camera delivers, used by the chain and
  // pipeline rows (a simulated frame's truth would add a 10-byte-per-pixel copy to each result).
  std::vector<Frame> camera_frames;
  std::vector<MetricFrame> ready;  // converted, calibrated, ΔL filled: input of later stages
  // The same with eq. 1 only: the table above is made up (its cost is real, its values are not
  // the simulator's wiggling), so the peer comparison's ground-truth counts use these frames.
  std::vector<MetricFrame> peer_ready;
  AccuracyOptions accuracy;  // ΔL with the noise-calibrated scale (FitBenchNoiseScale)
  [[nodiscard]] std::int64_t pixels() const { return std::int64_t{width} * height; }
};

Input MakeInput(int width, int height, int frames, double delta_l_scale,
                int integration_register = 40) {
  Input in;
  in.width = width;
  in.height = height;
  in.name = std::to_string(width) + "x" + std::to_string(height);
  sim::SimulatorOptions so;
  so.seed = 7;
  so.threads = 2;  // generating the inputs is not what is measured
  so.integration_time_register = integration_register;
  sim::SimulatedCamera cam(bench::MovingPavilion(),
                           sim::WithResolution(sim::ResolveCameraModel("sr2"), width, height), so);
  in.info = cam.Info();
  in.rays = MakeRayTable(in.info.intrinsics);
  in.accuracy.scale = delta_l_scale;
  // The calibration a wall measurement would give: the simulator's own fixed-pattern offsets,
  // plus a distance-dependent table so the costlier form of eq. 1 is the one timed.
  OffsetCalibration& c = in.calibration;
  c = bench::SimulatorOffsets(cam);
  in.calibration_eq1 = c;
  const OffsetCalibration& eq1_only = in.calibration_eq1;
  c.distance_correction = bench::MadeUpDistanceTable();
  c.Validate();
  for (int i = 0; i < frames; ++i) {
    std::optional<Frame> f = cam.Grab();
    if (!f) throw Error(ErrorCode::kInternal, "simulator returned no frame");
    MetricFrame m = ConvertToMetric(*f);
    MetricFrame p = m;
    ApplyCalibrationInPlace(m, c);
    ComputeDeltaLInto(m, in.accuracy, m.delta_l_m);
    ApplyCalibrationInPlace(p, eq1_only);
    ComputeDeltaLInto(p, in.accuracy, p.delta_l_m);
    Frame bare = *f;
    bare.truth.reset();
    in.frames.push_back(std::move(*f));
    in.camera_frames.push_back(std::move(bare));
    in.ready.push_back(std::move(m));
    in.peer_ready.push_back(std::move(p));
  }
  return in;
}

// Per-thread state: own copies of the inputs and own output buffers.
struct Workspace {
  const Input* input = nullptr;
  std::vector<Frame> frames;
  std::vector<Frame> camera_frames;
  std::vector<MetricFrame> ready;
  std::vector<MetricFrame> calibrate;  // calibrated in place, over and over
  std::vector<MetricFrame> pan_frames;
  MetricFrame metric;
  Image<float> delta_l;
  // Filter output, reused (FilterSet::Process, ApplyFiltersInto, UncertaintyFilterInto).
  Image<PixelFlags> raised;
  // One prepared filter set per filter row (key: the row's filter name), built for the rays.
  std::map<std::string, FilterSet> filter_sets;
  PanView pan_view;                // reused (MakePanViewInto), as a per-sweep loop does
  Image<float> smoothed;           // SpatialFilterInto output
  DenoisedChannels denoised;       // DenoiseInto output
  NeighbourPrediction prediction;  // PredictFromNeighboursInto output
  std::vector<NeighbourPrediction> predictions;  // one per ready frame, for the uncertainty row
  MetricFrame temporal_frame;
  std::optional<TemporalFilter> temporal;
  PointCloud cloud;
  std::optional<PaperChain> paper_chain;
  std::optional<PaperChain> paper_chain_eq1;  // the paper's calibration alone (no table)
  std::unique_ptr<IntegrationTimeController> controller;
  std::unique_ptr<IntegrationTimeController> model_controller;
  Frame scatter_out;                 // CompensateScatteringInto output
  std::vector<MetricFrame> pair_17;  // the ready frames as if taken at 17 MHz
  MetricFrame pair_work;             // CombineFramePair works in place on a copy
  std::optional<Pipeline> pipeline_default;
  std::optional<Pipeline> pipeline_all_filters;
  PipelineResult result;
  CopyBuffers copy;
  std::size_t copy_bytes = 0;
  std::uint64_t sink = 0;
};

FilterSetOptions AllFilters() {
  FilterSetOptions o;
  o.range_enabled = o.amplitude_enabled = o.saturation_enabled = o.accuracy_enabled = true;
  o.flying_pixel_enabled = o.jump_edge_enabled = o.weingarten_enabled = true;
  return o;
}

FilterSetOptions OnlyFilter(const std::string& name) {
  FilterSetOptions o;
  o.saturation_enabled = o.accuracy_enabled = false;
  if (name == "accuracy") o.accuracy_enabled = true;
  if (name == "amplitude") o.amplitude_enabled = true;
  if (name == "saturation") o.saturation_enabled = true;
  if (name == "range") o.range_enabled = true;
  if (name == "flying_pixel") o.flying_pixel_enabled = true;
  if (name == "jump_edge") o.jump_edge_enabled = true;
  if (name == "weingarten") o.weingarten_enabled = true;
  return o;
}

void InitWorkspace(Workspace& ws, const Input& in, std::size_t max_copy_bytes) {
  ws.input = &in;
  ws.frames = in.frames;
  ws.camera_frames = in.camera_frames;
  ws.ready = in.ready;
  for (const MetricFrame& f : ws.ready) ws.predictions.push_back(PredictFromNeighbours(f));
  ws.calibrate = in.ready;
  for (int k = 0; k < 5; ++k) {
    MetricFrame f = in.ready[static_cast<std::size_t>(k) % in.ready.size()];
    f.info.pan_angle_rad = (-60.0 + 30.0 * k) * kPi / 180.0;
    ws.pan_frames.push_back(std::move(f));
  }
  ControllerOptions paper_law;
  paper_law.kind = ControllerKind::kMayProportional;
  paper_law.gain_register_per_intensity = 2.5e-4;
  ws.controller = MakeController(paper_law);
  ControllerOptions model_based;
  model_based.kind = ControllerKind::kModelBased;
  ws.model_controller = MakeController(model_based);
  for (const MetricFrame& f : in.ready) {
    ws.pair_17.push_back(f);
    ws.pair_17.back().info.modulation_frequency_hz = 17e6;
  }
  for (const char* name : {"accuracy", "amplitude", "saturation", "range", "flying_pixel",
                           "jump_edge", "weingarten"}) {
    ws.filter_sets.emplace(name, FilterSet(OnlyFilter(name), in.rays));
  }
  ws.filter_sets.emplace("default", FilterSet(FilterSetOptions{}, in.rays));
  ws.filter_sets.emplace("all", FilterSet(AllFilters(), in.rays));
  ws.pair_work = in.ready.front();
  ws.temporal_frame = in.ready.front();
  ws.temporal.emplace();
  PaperChainOptions pc;
  pc.calibration = in.calibration;
  pc.accuracy = in.accuracy;
  ws.paper_chain.emplace(pc, in.info);
  pc.calibration = in.calibration_eq1;
  ws.paper_chain_eq1.emplace(pc, in.info);
  PipelineOptions po;
  po.calibration = in.calibration;
  po.accuracy = in.accuracy;
  ws.pipeline_default.emplace(po, in.info);
  po.filters = AllFilters();
  ws.pipeline_all_filters.emplace(po, in.info);
  ws.copy.Ensure(max_copy_bytes, 1);
}

// One stage: `run(ws, i)` processes frame i (mod the frame count) of the workspace.
struct Stage {
  std::string name;
  double bytes_per_pixel = 0;  // minimal memory traffic (read + write) of the stage
  int frames_per_call = 1;
  bool threadable = true;
  std::function<void(Workspace&, std::size_t)> run;
  // The distinct bytes the row touches over the frames, for its floor (bench_floor.h); not
  // stated (the hot floor) for the rows no target is stated for.
  Footprint footprint{};
};

void Sink(Workspace& ws, const void* p) { ws.sink += reinterpret_cast<std::uintptr_t>(p) & 1u; }

constexpr std::string_view kPanStage = "pan assembly (5 frames)";

// The pan assembly's traffic per input pixel: each input pixel's distance, amplitude, intensity,
// ΔL (4 bytes each) and flags (2) in, and the ray table (12 bytes a pixel) once per call (the
// frames share it); the merged cloud's kept points (x, y, z, amplitude, intensity, ΔL: 24 bytes,
// and 2 of flags) and the panorama's cells (distance 4, amplitude 4, colour 3) out; over the
// call's input frames.
double PanTraffic(const Workspace& ws) {
  const PanView& v = ws.pan_view;
  double in = 12.0 * static_cast<double>(ws.pan_frames.front().radial_distance_m.size());
  for (const MetricFrame& f : ws.pan_frames) {
    in += 18.0 * static_cast<double>(f.radial_distance_m.size());
  }
  const double out =
      26.0 * static_cast<double>(v.cloud.size()) + 11.0 * static_cast<double>(v.panorama.size());
  const double pixels = static_cast<double>(ws.pan_frames.front().radial_distance_m.size());
  return (in + out) / static_cast<double>(ws.pan_frames.size()) / pixels;
}

std::vector<Stage> MakeStages() {
  std::vector<Stage> s;
  // Bytes per pixel: read + write of the data the stage must touch at least.
  s.push_back({"metric conversion", 6 + 14, 1, true, [](Workspace& ws, std::size_t i) {
                 ConvertToMetricInto(ws.frames[i % ws.frames.size()], {}, ws.metric);
                 Sink(ws, ws.metric.radial_distance_m.data());
               }});
  s.push_back({"calibration (eq. 1 + table)", 4 + 4 + 2 + 2 + 4 + 2, 1, true,
               [](Workspace& ws, std::size_t i) {
                 MetricFrame& m = ws.calibrate[i % ws.calibrate.size()];
                 ApplyCalibrationInPlace(m, ws.input->calibration);
                 Sink(ws, m.radial_distance_m.data());
               }});
  s.push_back({"delta L (eq. 2)", 4 + 4 + 4, 1, true, [](Workspace& ws, std::size_t i) {
                 ComputeDeltaLInto(ws.ready[i % ws.ready.size()], ws.input->accuracy, ws.delta_l);
                 Sink(ws, ws.delta_l.data());
               }});
  const std::pair<const char*, const char*> filters[] = {
      {"filter: accuracy threshold", "accuracy"}, {"filter: amplitude", "amplitude"},
      {"filter: saturation", "saturation"},       {"filter: range", "range"},
      {"filter: flying pixel", "flying_pixel"},   {"filter: jump edge", "jump_edge"},
      {"filter: Weingarten cells", "weingarten"}};
  // Channels in, the frame's flags in (2, the neighbourhood filters only: the pixels to ignore),
  // the output flags out (2). The per-pixel thresholds read no flags.
  const std::map<std::string, double> filter_bytes = {
      {"accuracy", 4 + 2},
      {"amplitude", 4 + 2},
      {"saturation", 4 + 4 + 2},
      {"range", 4 + 2},
      // The flying-pixel filter reads the amplitude as well as the distance (its contrast test).
      {"flying_pixel", 4 + 4 + 2 + 2},
      {"jump_edge", 4 + 12 + 2 + 2},
      {"weingarten", 4 + 12 + 2 + 2}};
  // The filters as a camera's loop runs them: a FilterSet built once for the camera's rays.
  auto filter_row = [](std::string key) {
    return [key](Workspace& ws, std::size_t i) {
      ws.filter_sets.at(key).Process(ws.ready[i % ws.ready.size()], ws.raised);
      Sink(ws, ws.raised.data());
    };
  };
  // Footprints of the filter rows: the output flags (2 B/px) and the ray table (12, jump edge,
  // cells and the full set) are the same on every call; the rest of the traffic, the channels and
  // flags the row reads, is the frame's.
  auto filter_footprint = [](double traffic, bool rays) {
    const double fixed = 2.0 + (rays ? 12.0 : 0.0);
    return Footprint{traffic - fixed, fixed};
  };
  for (const auto& [label, key] : filters) {
    const double bytes = filter_bytes.at(key);
    const std::string_view k = key;
    s.push_back({label, bytes, 1, true, filter_row(key),
                 filter_footprint(bytes, k == "jump_edge" || k == "weingarten")});
  }
  // Amplitude, intensity and ΔL in (the saturation and accuracy thresholds), the flags out.
  s.push_back({"filters: paper default set", 4 + 4 + 4 + 2, 1, true, filter_row("default"),
               filter_footprint(4 + 4 + 4 + 2, false)});
  constexpr double kAllBytes = 4 + 4 + 4 + 4 + 12 + 2 + 2;
  s.push_back({"filters: full set (all 7)", kAllBytes, 1, true, filter_row("all"),
               filter_footprint(kAllBytes, true)});
  // The free function re-derives (or checks) what FilterSet prepared once, on every call.
  const FilterSetOptions all = AllFilters();
  s.push_back({"filters: full set, ApplyFilters", kAllBytes, 1, true,
               [all](Workspace& ws, std::size_t i) {
                 ApplyFiltersInto(ws.ready[i % ws.ready.size()], ws.input->rays, all, ws.raised);
                 Sink(ws, ws.raised.data());
               },
               filter_footprint(kAllBytes, true)});
  // Smoothing (not in the paper): distance + flags (+ ΔL) in, distance out.
  for (const SpatialFilterKind kind : {SpatialFilterKind::kMedian, SpatialFilterKind::kBilateral}) {
    SpatialFilterOptions so;
    so.kind = kind;
    s.push_back({std::string("smoothing: ") + std::string(SpatialFilterKindName(kind)) + " 3x3",
                 kind == SpatialFilterKind::kMedian ? 10.0 : 14.0, 1, true,
                 [so](Workspace& ws, std::size_t i) {
                   SpatialFilterInto(ws.ready[i % ws.ready.size()], so, ws.smoothed);
                   Sink(ws, ws.smoothed.data());
                 }});
  }
  // Temporal filter: distance (restored from the ready frame: 4 + 4), ΔL and flags in, distance
  // and the per-pixel state (mean 4, variance 4, count 2, gap, outlier, drift 1 each) both ways.
  s.push_back(
      {"temporal filter", 4 + 4 + 4 + 2 + 4 + 2 * 13, 1, true, [](Workspace& ws, std::size_t i) {
         const MetricFrame& in = ws.ready[i % ws.ready.size()];
         MetricFrame& m = ws.temporal_frame;
         std::copy(in.radial_distance_m.data(),
                   in.radial_distance_m.data() + in.radial_distance_m.size(),
                   m.radial_distance_m.data());
         ws.temporal->Process(m);
         Sink(ws, m.radial_distance_m.data());
       }});
  s.push_back(
      {"point cloud", 4 + 4 + 4 + 4 + 2 + 12 + 24 + 2, 1, true, [](Workspace& ws, std::size_t i) {
         MakePointCloudInto(ws.ready[i % ws.ready.size()], ws.input->rays, ws.cloud);
         Sink(ws, ws.cloud.x.data());
       }});
  // Footprint: the frame's distance and flags; the image (3), allocated again of the same size.
  s.push_back({"false colour", 4 + 2 + 3, 1, true,
               [](Workspace& ws, std::size_t i) {
                 const Image<Rgb8> img = FalseColor(ws.ready[i % ws.ready.size()], {});
                 Sink(ws, img.data());
               },
               Footprint{4 + 2, 3}});
  s.push_back({"controller (May P)", 4 + 2, 1, true, [](Workspace& ws, std::size_t i) {
                 ws.sink += static_cast<std::uint64_t>(
                     ws.controller->Update(ws.ready[i % ws.ready.size()]));
               }});
  // Not in the paper (issue 18, docs/beyond.md).
  s.push_back({"controller (model-based)", 4 + 4 + 2, 1, true, [](Workspace& ws, std::size_t i) {
                 ws.sink += static_cast<std::uint64_t>(
                     ws.model_controller->Update(ws.ready[i % ws.ready.size()]));
               }});
  {
    // A fitted noise model with every channel but confidence: in d, A, I, out ΔL.
    AccuracyOptions fitted;
    NoiseModel model;
    model.intercept = -2.0;
    model.log_amplitude = -0.8;
    model.log_intensity = 0.4;
    model.log_distance = 0.1;
    model.amplitude_fraction = 0.3;
    model.amplitude_ref = 20000.0;
    fitted.model = model;
    s.push_back({"delta L (fitted noise model)", 4 + 4 + 4 + 4, 1, true,
                 [fitted](Workspace& ws, std::size_t i) {
                   ComputeDeltaLInto(ws.ready[i % ws.ready.size()], fitted, ws.delta_l);
                   Sink(ws, ws.delta_l.data());
                 }});
  }
  {
    // Two lobes as the estimator finds them on the simulated SR-2, three iterations: the three
    // registers in and out.
    ScatteringOptions so;
    so.lobes = {{0.0005, 8.0}, {0.0008, 48.0}};
    s.push_back({"scattering compensation (2 lobes, 3 iterations)", 6 + 6, 1, true,
                 [so](Workspace& ws, std::size_t i) {
                   CompensateScatteringInto(ws.frames[i % ws.frames.size()], so, ws.scatter_out);
                   Sink(ws, ws.scatter_out.distance.data());
                 }});
  }
  // Dual-frequency unwrapping of a frame with its predecessor: the current frame's distance,
  // ΔL and flags are restored (4 + 4 + 2 both ways) and both frames' read.
  // Denoising before the pair (not in the paper): distance, amplitude, ΔL and flags in,
  // distance, amplitude and ΔL out.
  s.push_back({"denoise 3x3 (before the pair)", 4 + 4 + 4 + 2 + 12, 1, true,
               [](Workspace& ws, std::size_t i) {
                 DenoiseInto(ws.ready[i % ws.ready.size()], {}, ws.denoised);
                 Sink(ws, ws.denoised.radial_distance_m.data());
               }});
  // The same with a plane fitted to each support: the rays' x, y and z read as well.
  s.push_back({"denoise 3x3, fitted plane", 4 + 4 + 4 + 2 + 12 + 12, 1, true,
               [](Workspace& ws, std::size_t i) {
                 DenoiseOptions o;
                 o.fit_plane = true;
                 DenoiseInto(ws.ready[i % ws.ready.size()], ws.input->rays, o, ws.denoised);
                 Sink(ws, ws.denoised.radial_distance_m.data());
               }});
  // The neighbours' prediction (not in the paper): distance, ΔL and flags in, the prediction
  // and its σ out.
  s.push_back(
      {"neighbour prediction 7x7", 4 + 4 + 2 + 8, 1, true, [](Workspace& ws, std::size_t i) {
         PredictFromNeighboursInto(ws.ready[i % ws.ready.size()], {}, ws.prediction);
         Sink(ws, ws.prediction.distance_m.data());
       }});
  // With the amplitudes, so that the two-returns checks run as in a pipeline: the per-pixel one
  // and the pooled one over 7x7 windows (the defaults). Both frames' distance, ΔL, amplitude and
  // flags read, the current frame's distance, ΔL and flags written, plus the copy that restores
  // them.
  const auto pair_row = [](int radius_px) {
    return [radius_px](Workspace& ws, std::size_t i) {
      const MetricFrame& in = ws.pair_17[i % ws.pair_17.size()];
      MetricFrame& m = ws.pair_work;
      m.radial_distance_m = in.radial_distance_m;
      m.delta_l_m = in.delta_l_m;
      m.amplitude = in.amplitude;
      m.flags = in.flags;
      m.info = in.info;
      FramePairOptions o;
      o.two_returns_radius_px = radius_px;
      CombineFramePair(ws.ready[(i + 1) % ws.ready.size()], m, o);
      Sink(ws, m.radial_distance_m.data());
    };
  };
  s.push_back({"frame pair (dual-frequency unwrap)", 14 + 14 + 10 + 14, 1, true, pair_row(3)});
  s.push_back({"frame pair, per-pixel checks only", 14 + 14 + 10 + 14, 1, true, pair_row(0)});
  s.push_back({"filter: uncertainty (ΔL + edges)", 4 + 4 + 2 + 2, 1, true,
               [](Workspace& ws, std::size_t i) {
                 UncertaintyFilterInto(ws.ready[i % ws.ready.size()], {}, ws.raised);
                 Sink(ws, ws.raised.data());
               },
               filter_footprint(4 + 4 + 2 + 2, false)});
  // The same judging each reading's residual against the neighbours' prediction (made before,
  // not timed here): the prediction's distance and σ read as well.
  s.push_back({"filter: uncertainty with the neighbours' prediction", 4 + 4 + 2 + 2 + 8, 1, true,
               [](Workspace& ws, std::size_t i) {
                 const std::size_t k = i % ws.ready.size();
                 UncertaintyFilterInto(ws.ready[k], {}, ws.raised, &ws.predictions[k]);
                 Sink(ws, ws.raised.data());
               }});
  // Issue 18's best rows' uncertainty: the prediction and own-side edge terms, then with edge
  // pixels unmixed as well (their amplitudes read too: 4 more bytes a pixel).
  s.push_back({"filter: uncertainty, prediction + own-side edges", 4 + 4 + 2 + 2 + 8, 1, true,
               [](Workspace& ws, std::size_t i) {
                 const std::size_t k = i % ws.ready.size();
                 UncertaintyOptions o;
                 o.extrapolate_edges = true;
                 UncertaintyFilterInto(ws.ready[k], o, ws.raised, &ws.predictions[k]);
                 Sink(ws, ws.raised.data());
               }});
  s.push_back({"filter: uncertainty, prediction + own-side edges + unmixing", 4 + 4 + 4 + 2 + 2 + 8,
               1, true, [](Workspace& ws, std::size_t i) {
                 const std::size_t k = i % ws.ready.size();
                 UncertaintyOptions o;
                 o.extrapolate_edges = true;
                 o.unmix_edges = true;
                 UncertaintyFilterInto(ws.ready[k], o, ws.raised, &ws.predictions[k]);
                 Sink(ws, ws.raised.data());
               }});
  // Five frames at -60..60 degrees into the 180-degree cloud and panorama; per input frame
  // (traffic: PanTraffic).
  s.push_back({std::string(kPanStage), 0, 5, true, [](Workspace& ws, std::size_t) {
                 MakePanViewInto(ws.pan_frames, ws.input->rays, {}, ws.pan_view);
                 Sink(ws, ws.pan_view.panorama.data());
               }});
  // The issue-4 target: metric + calibration (with the table) + ΔL + threshold + point cloud,
  // fused into one pass (PaperChain), on frames as a camera delivers them (no ground truth).
  // Floor: registers, offsets and rays in; metric frame, ΔL and cloud out.
  constexpr double kChainBytes = 6 + 4 + 12 + 14 + 4 + 26;
  // Only the registers are the call's frame's; the tables and the outputs are the same buffers.
  constexpr Footprint kChainFootprint{6, kChainBytes - 6};
  s.push_back({"PAPER CHAIN (target)", kChainBytes, 1, true,
               [](Workspace& ws, std::size_t i) {
                 ws.paper_chain->Process(ws.camera_frames[i % ws.camera_frames.size()], ws.metric,
                                         ws.cloud);
                 Sink(ws, ws.cloud.x.data());
               },
               kChainFootprint});
  // The chain with the paper's calibration (eq. 1, section II-B) and without tofcam's
  // distance-dependent table (issue 4's "go further"): the table lookup is half of the chain.
  s.push_back({"paper chain, eq. 1 only (no table)", kChainBytes, 1, true,
               [](Workspace& ws, std::size_t i) {
                 ws.paper_chain_eq1->Process(ws.camera_frames[i % ws.camera_frames.size()],
                                             ws.metric, ws.cloud);
                 Sink(ws, ws.cloud.x.data());
               },
               kChainFootprint});
  // The same stages called one after the other on whole frames (same results).
  s.push_back({"paper chain, stage by stage", kChainBytes, 1, true,
               [](Workspace& ws, std::size_t i) {
                 MetricFrame& m = ws.metric;
                 ConvertToMetricInto(ws.camera_frames[i % ws.camera_frames.size()], {}, m);
                 ApplyCalibrationInPlace(m, ws.input->calibration);
                 ComputeDeltaLInto(m, ws.input->accuracy, m.delta_l_m);
                 static const FilterSetOptions threshold = OnlyFilter("accuracy");
                 ApplyFiltersInto(m, ws.input->rays, threshold, ws.raised);
                 MergeFlags(m, ws.raised);
                 MakePointCloudInto(m, ws.input->rays, ws.cloud);
                 Sink(ws, ws.cloud.x.data());
               },
               kChainFootprint});
  s.push_back({"PIPELINE (Pipeline::Process, defaults)", kChainBytes, 1, true,
               [](Workspace& ws, std::size_t i) {
                 ws.pipeline_default->Process(ws.camera_frames[i % ws.camera_frames.size()],
                                              ws.result);
                 Sink(ws, ws.result.cloud.x.data());
               }});
  s.push_back({"PIPELINE + all filters", kChainBytes, 1, true, [](Workspace& ws, std::size_t i) {
                 ws.pipeline_all_filters->Process(ws.camera_frames[i % ws.camera_frames.size()],
                                                  ws.result);
                 Sink(ws, ws.result.cloud.x.data());
               }});
  return s;
}

// Wall time (ns) of `threads` threads each calling fn `reps` times on its own workspace.
double RunBatch(std::vector<Workspace>& ws, int threads,
                const std::function<void(Workspace&, std::size_t)>& fn, std::size_t reps) {
  const auto start = Clock::now();
  if (threads == 1) {
    for (std::size_t r = 0; r < reps; ++r) fn(ws[0], r);
  } else {
    std::vector<std::thread> pool;
    for (int t = 1; t < threads; ++t) {
      pool.emplace_back([&, t] {
        for (std::size_t r = 0; r < reps; ++r) fn(ws[static_cast<std::size_t>(t)], r);
      });
    }
    for (std::size_t r = 0; r < reps; ++r) fn(ws[0], r);
    for (auto& th : pool) th.join();
  }
  return std::chrono::duration<double, std::nano>(Clock::now() - start).count();
}

// Wall ns per call (per thread: a call on each thread counts as `threads` calls), median of 5.
double TimePerCall(std::vector<Workspace>& ws, int threads,
                   const std::function<void(Workspace&, std::size_t)>& fn, double min_time_s) {
  const double batch_ns = min_time_s * 1e9 / 5;
  std::size_t reps = 1;
  RunBatch(ws, threads, fn, 2);  // warm-up: buffers sized, caches and branch predictors primed
  for (;;) {
    const double t = RunBatch(ws, threads, fn, reps);
    if (t >= batch_ns || reps >= (std::size_t{1} << 30)) break;
    reps = std::max(reps * 2, static_cast<std::size_t>(reps * batch_ns / std::max(t, 1.0)));
  }
  std::vector<double> times;
  for (int b = 0; b < 5; ++b) times.push_back(RunBatch(ws, threads, fn, reps));
  std::sort(times.begin(), times.end());
  return times[2] / static_cast<double>(reps * static_cast<std::size_t>(threads));
}

struct Row {
  std::string stage;
  std::string resolution;
  std::int64_t pixels = 0;
  int threads = 1;
  double ns_per_frame = 0;
  double bytes_per_pixel = 0;
  double memcpy_ns = 0;
  std::string note;
  double memcpy_hot_ns = 0;              // the floor with one source copied again and again
  double ratio_hot = 0;                  // median over the rounds of stage / that floor
  std::size_t floor_sources = 1;         // the floor's sources (FloorSources, then the cap)
  double footprint_bytes_per_pixel = 0;  // the row's stated footprint over the frames; 0: none
  // Spread over the rounds: ns per frame (min, max) and, with a floor, the stage / memcpy ratio
  // of each round of back-to-back batches (median, min, max).
  double ns_min = 0, ns_max = 0;
  double ratio = 0, ratio_min = 0, ratio_max = 0;
};

// A stage and its memcpy floors timed in rounds of back-to-back batches (stage, floor, hot floor;
// the floors swap places every other round), so load that comes and goes hits all alike: per
// round the ratios stage / floor and stage / hot floor. Medians of kRounds rounds, with the
// minimum and maximum ratio to the floor as the spread.
struct Paired {
  double stage_ns = 0, stage_min = 0, stage_max = 0, floor_ns = 0;
  double hot_floor_ns = 0, hot_ratio = 0;  // against one source copied again and again
  double ratio = 0, ratio_min = 0, ratio_max = 0;
};
constexpr int kRounds = 7;

// Repetitions of fn that take about a fifth of min_time_s (after a warm-up).
std::size_t CalibrateReps(std::vector<Workspace>& ws, int threads,
                          const std::function<void(Workspace&, std::size_t)>& fn,
                          double min_time_s) {
  const double batch_ns = min_time_s * 1e9 / 5;
  std::size_t reps = 1;
  RunBatch(ws, threads, fn, 2);
  for (;;) {
    const double t = RunBatch(ws, threads, fn, reps);
    if (t >= batch_ns || reps >= (std::size_t{1} << 30)) return reps;
    reps = std::max(reps * 2, static_cast<std::size_t>(reps * batch_ns / std::max(t, 1.0)));
  }
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

Paired TimeAgainstFloor(std::vector<Workspace>& ws, int threads,
                        const std::function<void(Workspace&, std::size_t)>& fn,
                        std::size_t floor_bytes, double min_time_s) {
  // The floor copies source r mod the source count (CopyBuffers); the hot floor one source again
  // and again, as the floor did before the fifteenth session (2026-12-08).
  const std::function<void(Workspace&, std::size_t)> copy = [](Workspace& w, std::size_t r) {
    std::memcpy(w.copy.dst(), w.copy.src(r), w.copy_bytes);
    Sink(w, w.copy.dst());
  };
  const std::function<void(Workspace&, std::size_t)> hot_copy = [](Workspace& w, std::size_t) {
    std::memcpy(w.copy.dst(), w.copy.src(0), w.copy_bytes);
    Sink(w, w.copy.dst());
  };
  for (auto& w : ws) w.copy_bytes = floor_bytes;
  // Every batch starts again at repetition 0: a batch of fewer repetitions than frames (or
  // sources) would touch fewer bytes than the footprint the floor was sized for.
  const std::size_t frames = ws.front().ready.size(), sources = ws.front().copy.sources();
  const std::size_t reps = std::max(CalibrateReps(ws, threads, fn, min_time_s), frames);
  const std::size_t floor_reps = std::max(CalibrateReps(ws, threads, copy, min_time_s), sources);
  auto per_call = [threads](double ns, std::size_t n) {
    return ns / static_cast<double>(n * static_cast<std::size_t>(threads));
  };
  auto time_floor = [&](const std::function<void(Workspace&, std::size_t)>& f) {
    return per_call(RunBatch(ws, threads, f, floor_reps), floor_reps);
  };
  std::vector<double> stage, floor, hot, ratio, hot_ratio;
  for (int b = 0; b < kRounds; ++b) {
    const double ts = per_call(RunBatch(ws, threads, fn, reps), reps);
    // The batch right after the stage runs slower (at 1 MP a few per cent, up to 20 %, on the
    // Zen 5 of docs/benchmarks.md): the two floors take turns in that place. With one source
    // they are the same copy, timed once.
    double tf = 0, th = 0;
    if (sources == 1) {
      tf = th = time_floor(copy);
    } else if (b % 2 == 0) {
      tf = time_floor(copy);
      th = time_floor(hot_copy);
    } else {
      th = time_floor(hot_copy);
      tf = time_floor(copy);
    }
    stage.push_back(ts);
    floor.push_back(tf);
    hot.push_back(th);
    ratio.push_back(ts / tf);
    hot_ratio.push_back(ts / th);
  }
  Paired p;
  p.hot_floor_ns = Median(hot);
  p.hot_ratio = Median(hot_ratio);
  p.stage_ns = Median(stage);
  p.stage_min = *std::min_element(stage.begin(), stage.end());
  p.stage_max = *std::max_element(stage.begin(), stage.end());
  p.floor_ns = Median(floor);
  p.ratio = Median(ratio);
  p.ratio_min = *std::min_element(ratio.begin(), ratio.end());
  p.ratio_max = *std::max_element(ratio.begin(), ratio.end());
  return p;
}

double MemcpyNs(std::vector<Workspace>& ws, int threads, std::size_t bytes, double min_time_s) {
  for (auto& w : ws) w.copy_bytes = bytes;
  return TimePerCall(
      ws, threads,
      [](Workspace& w, std::size_t) {
        std::memcpy(w.copy.dst(), w.copy.src(0), w.copy_bytes);
        Sink(w, w.copy.dst());
      },
      min_time_s);
}

// Appends `frames` to a fresh recording / reads them back; ns per frame, median of 3 runs.
std::pair<double, double> TimeRecording(const Input& in, const std::filesystem::path& dir,
                                        const RecordingOptions& options) {
  const std::filesystem::path path = dir / ("bench_" + in.name + ".h5");
  std::vector<double> write_ns, read_ns;
  for (int run = 0; run < 3; ++run) {
    std::filesystem::remove(path);
    {
      RecordingWriter w(path, in.info, options);
      const auto t0 = Clock::now();
      for (const Frame& f : in.frames) w.Append(f);
      w.Close();
      write_ns.push_back(std::chrono::duration<double, std::nano>(Clock::now() - t0).count());
    }
    RecordingReader r(path);
    const auto t0 = Clock::now();
    std::uint64_t sink = 0;
    for (std::size_t i = 0; i < r.frame_count(); ++i) sink += r.Read(i).distance[0];
    read_ns.push_back(std::chrono::duration<double, std::nano>(Clock::now() - t0).count() +
                      static_cast<double>(sink & 0));
  }
  std::filesystem::remove(path);
  std::sort(write_ns.begin(), write_ns.end());
  std::sort(read_ns.begin(), read_ns.end());
  const double n = static_cast<double>(in.frames.size());
  return {write_ns[1] / n, read_ns[1] / n};
}

struct SimRow {
  std::string name;
  int threads = 1;
  double frames_per_s = 0;  // median of 5 batches
  double fps_min = 0, fps_max = 0;
};

// Frames/s of Grab(), median of 5 batches of at least min_time_s / 5 and 3 frames each, with the
// slowest and fastest batch.
SimRow SimulatorFps(std::string name, sim::Scene scene, const sim::CameraModel& model, int threads,
                    double min_time_s, bool planar_shortcut = false) {
  sim::SimulatorOptions so;
  so.seed = 7;
  so.threads = threads;
  so.planar_shortcut = planar_shortcut;
  so.integration_time_register = 40;
  sim::SimulatedCamera cam(std::move(scene), model, so);
  for (int i = 0; i < 2; ++i) (void)cam.Grab();
  std::vector<double> fps;
  for (int b = 0; b < 5; ++b) {
    const auto t0 = Clock::now();
    int n = 0;
    double elapsed = 0;
    do {
      (void)cam.Grab();
      ++n;
      elapsed = std::chrono::duration<double>(Clock::now() - t0).count();
    } while (elapsed < min_time_s / 5 || n < 3);
    fps.push_back(n / elapsed);
  }
  SimRow r;
  r.name = std::move(name);
  r.threads = threads;
  r.frames_per_s = Median(fps);
  r.fps_min = *std::min_element(fps.begin(), fps.end());
  r.fps_max = *std::max_element(fps.begin(), fps.end());
  return r;
}

// Bad = |measured - true| > 5 cm or no true surface (the frame_stats definition).
bool IsBad(const MetricFrame& m, std::size_t i) {
  const float truth = m.truth->radial_distance_m[i];
  const float d = m.radial_distance_m[i];
  return !std::isfinite(truth) || !std::isfinite(d) || std::fabs(d - truth) > 0.05f;
}

// The register the may-incremental controller settles to on the benchmark scene: the SR-2 model
// in the pavilion at the moving camera's start pose (held still, so there is something to settle
// on; the peer frames are the first frames of the drive, near that pose), seed 7, eq.-1
// calibration, the controller's defaults from c_0 = 40, frame t setting the register of frame
// t + 1. Settled: the register unchanged for 10 frames (at most `frames` frames). The scaled
// models keep the SR-2 pixel pitch and optics, so the same register exposes them alike.
int SettledRegister(int frames, std::vector<int>& trajectory) {
  sim::SimulatedCamera cam = bench::StaticStartCamera(40);
  PipelineOptions po;
  po.controller.kind = ControllerKind::kMayIncremental;
  po.calibration = bench::SimulatorOffsets(cam);
  Pipeline pipeline(po, cam.Info());
  cam.SetIntegrationTimeRegister(pipeline.InitialIntegrationRegister());
  PipelineResult result;
  trajectory.clear();
  for (int i = 0; i < frames; ++i) {
    std::optional<Frame> f = cam.Grab();
    if (!f) throw Error(ErrorCode::kInternal, "simulator returned no frame");
    trajectory.push_back(f->info.integration_time_register);
    pipeline.Process(*f, result);
    cam.SetIntegrationTimeRegister(result.next_integration_register);
    const std::size_t t = trajectory.size();
    if (t >= 10 && std::all_of(trajectory.end() - 10, trajectory.end(),
                               [&](int r) { return r == trajectory.back(); })) {
      return trajectory.back();
    }
  }
  throw Error(ErrorCode::kInternal, "the may-incremental controller did not settle within " +
                                        std::to_string(frames) + " frames");
}

// Writes, for bench/peers/peer_outlier_removal.py, each frame's cloud (every pixel with a
// distance: float32 x, y, z, bad) and tofcam's filter results on the same points.
void ExportPeers(const std::vector<Input>& inputs, const std::filesystem::path& dir,
                 double min_time_s, json& out) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    throw Error(ErrorCode::kIo,
                "--export-peers: cannot create folder " + dir.string() + ": " + ec.message());
  }
  json res = json::array();
  const std::pair<const char*, FilterSetOptions> configs[] = {
      {"tofcam accuracy threshold", OnlyFilter("accuracy")},
      {"tofcam amplitude (< 100)", OnlyFilter("amplitude")},
      {"tofcam jump edge", OnlyFilter("jump_edge")},
      {"tofcam flying pixel", OnlyFilter("flying_pixel")},
      {"tofcam Weingarten cells", OnlyFilter("weingarten")},
      {"tofcam accuracy + jump edge + flying pixel",
       [] {
         FilterSetOptions o = OnlyFilter("accuracy");
         o.jump_edge_enabled = o.flying_pixel_enabled = true;
         return o;
       }()},
      {"tofcam full set (all 7)", AllFilters()}};
  for (const Input& in : inputs) {
    if (in.pixels() > 640 * 480) continue;  // peers take seconds per megapixel frame
    json files = json::array();
    for (std::size_t f = 0; f < in.peer_ready.size(); ++f) {
      const MetricFrame& m = in.peer_ready[f];
      PointCloudOptions co;
      co.nan_mask = kRejectMask;
      const PointCloud cloud = MakePointCloud(m, in.rays, co);
      std::vector<float> rows;
      for (std::size_t i = 0; i < cloud.size(); ++i) {
        if (!cloud.IsValid(i)) continue;
        rows.insert(rows.end(), {cloud.x[i], cloud.y[i], cloud.z[i], IsBad(m, i) ? 1.0f : 0.0f});
      }
      const std::string name = in.name + "_frame" + std::to_string(f) + ".f32";
      WriteFileAtomically(dir / name, std::string_view(reinterpret_cast<const char*>(rows.data()),
                                                       rows.size() * sizeof(float)));
      files.push_back(name);
    }
    for (const auto& [label, options] : configs) {
      std::int64_t bad = 0, good = 0, bad_removed = 0, good_lost = 0;
      for (const MetricFrame& m : in.peer_ready) {
        const Image<PixelFlags> flags = ApplyFilters(m, in.rays, options);  // once, for counts
        for (std::size_t i = 0; i < m.radial_distance_m.size(); ++i) {
          if (!m.flags[i].Valid() || !std::isfinite(m.radial_distance_m[i])) continue;
          const bool removed = !flags[i].Valid();
          if (IsBad(m, i)) {
            ++bad;
            bad_removed += removed ? 1 : 0;
          } else {
            ++good;
            good_lost += removed ? 1 : 0;
          }
        }
      }
      std::vector<Workspace> ws(1);
      ws[0].input = &in;
      ws[0].ready = in.peer_ready;
      const FilterSetOptions o = options;
      const double ns = TimePerCall(
          ws, 1,
          [o](Workspace& w, std::size_t i) {
            ApplyFiltersInto(w.ready[i % w.ready.size()], w.input->rays, o, w.raised);
            Sink(w, w.raised.data());
          },
          min_time_s);
      res.push_back({{"method", label},
                     {"resolution", in.name},
                     {"frames", in.peer_ready.size()},
                     {"ms_per_frame", ns * 1e-6},
                     {"bad_points", bad},
                     {"good_points", good},
                     {"bad_removed", bad_removed},
                     {"good_lost", good_lost}});
    }
    out["clouds"][in.name] = files;
  }
  out["tofcam"] = res;
  WriteFileAtomically(dir / "tofcam_filters.json", out.dump(2) + "\n");
}

std::string Machine() {
  std::string cpu = "unknown";
  std::ifstream f("/proc/cpuinfo");
  for (std::string line; std::getline(f, line);) {
    if (line.rfind("model name", 0) == 0) {
      cpu = line.substr(line.find(':') + 2);
      break;
    }
  }
  return cpu + ", " + std::to_string(std::thread::hardware_concurrency()) + " hardware threads";
}

void RunBench(const BenchOptions& o) {
  if (o.frames < 1 || o.frames > 1000) {
    throw Error(ErrorCode::kInvalidArgument,
                "--frames must be in [1, 1000], got " + std::to_string(o.frames));
  }
  if (o.threads != 0 && o.threads != 1 && o.threads != 2) {
    throw Error(ErrorCode::kInvalidArgument,
                "--threads must be 1 or 2, got " + std::to_string(o.threads));
  }
  if (!(o.min_time_s > 0 && o.min_time_s <= 60)) {
    throw Error(ErrorCode::kInvalidArgument,
                "--min-time-s must be in (0, 60], got " + std::to_string(o.min_time_s));
  }
  for (const std::string& z : o.sizes) {
    if (z != "160x124" && z != "640x480" && z != "1024x1024") {
      throw Error(ErrorCode::kInvalidArgument,
                  "--size must be 160x124, 640x480 or 1024x1024, got '" + z + "'");
    }
  }
  // --stage: the stage rows whose name contains one of the texts, ignoring case; the memory
  // bandwidth, recording and simulator rows are not stages and are left out then.
  std::vector<Stage> stages = MakeStages();
  const bool stages_only = !o.stage_filters.empty();
  if (stages_only) {
    const auto lower = [](std::string t) {
      for (char& ch : t) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
      return t;
    };
    const auto matches = [&](const Stage& st, const std::string& text) {
      return lower(st.name).find(lower(text)) != std::string::npos;
    };
    std::string names;
    for (const Stage& st : stages) names += (names.empty() ? "" : ", ") + st.name;
    for (const std::string& text : o.stage_filters) {
      if (std::none_of(stages.begin(), stages.end(),
                       [&](const Stage& st) { return matches(st, text); })) {
        throw Error(ErrorCode::kInvalidArgument,
                    "--stage '" + text + "' matches no stage (stages: " + names + ")");
      }
    }
    std::erase_if(stages, [&](const Stage& st) {
      return std::none_of(o.stage_filters.begin(), o.stage_filters.end(),
                          [&](const std::string& text) { return matches(st, text); });
    });
  }
  const std::pair<int, int> all_sizes[] = {{160, 124}, {640, 480}, {1024, 1024}};
  std::vector<std::pair<int, int>> sizes;
  for (const auto& [w, h] : all_sizes) {
    const std::string name = std::to_string(w) + "x" + std::to_string(h);
    if (o.sizes.empty() || std::find(o.sizes.begin(), o.sizes.end(), name) != o.sizes.end()) {
      sizes.emplace_back(w, h);
    }
  }
  std::vector<int> thread_counts;
  if (o.threads != 2) thread_counts.push_back(1);
  if (o.threads != 1) thread_counts.push_back(2);
  auto progress = [&](const std::string& s) { std::fprintf(stderr, "bench: %s\n", s.c_str()); };

  json report;
  report["machine"] = Machine();
  report["compiler"] = __VERSION__;
  report["frames"] = o.frames;
  report["min_time_s"] = o.min_time_s;
  report["floor"] =
      "memcpy of the stage's minimal traffic (read + write), cycling through memcpy_sources "
      "sources, as many as touch at most the stage's own distinct bytes over the frames "
      "(footprint_bytes_per_pixel; one where the row states none, where one more would pass it, "
      "or past 256 MiB of sources; memcpy_us, ratio_to_memcpy), and from one source again and "
      "again (memcpy_hot_us, ratio_to_hot_memcpy)";

  // Memory bandwidth: a 256 MiB memcpy (read + write counted).
  if (!o.peers_only && !stages_only) {
    constexpr std::size_t kBytes = std::size_t{256} << 20;
    // One workspace per thread of the largest thread count asked for.
    std::vector<Workspace> ws(static_cast<std::size_t>(thread_counts.back()));
    for (auto& w : ws) w.copy.Ensure(kBytes, 1);
    for (int t : thread_counts) {
      const double ns = MemcpyNs(ws, t, kBytes, std::max(o.min_time_s, 0.5));
      report["memory_bandwidth_gb_s"][std::to_string(t) + "_threads"] = 2.0 * kBytes / ns * t;
    }
  }

  progress("noise calibration (ΔL scale from 16 static SR-2 frames)");
  const double delta_l_scale = bench::FitBenchNoiseScale();
  progress("ΔL scale " + std::to_string(delta_l_scale));
  report["delta_l_scale"] = delta_l_scale;

  std::vector<Input> inputs;
  for (const auto& [w, h] : sizes) {
    if (o.peers_only) break;
    progress("simulating " + std::to_string(o.frames) + " frames at " + std::to_string(w) + "x" +
             std::to_string(h));
    inputs.push_back(MakeInput(w, h, o.frames, delta_l_scale));
  }

  std::vector<Row> rows;
  double max_bpp = 0;
  for (const Stage& s : stages) max_bpp = std::max(max_bpp, s.bytes_per_pixel);
  for (const Input& in : inputs) {
    progress("stages at " + in.name);
    // One workspace per thread of the largest thread count asked for.
    std::vector<Workspace> ws(static_cast<std::size_t>(thread_counts.back()));
    const auto copy_max = static_cast<std::size_t>(max_bpp / 2 * static_cast<double>(in.pixels()));
    for (auto& w : ws) InitWorkspace(w, in, copy_max);
    for (const Stage& s : stages) {
      for (int t : thread_counts) {
        if (t > 1 && !s.threadable) continue;
        Row r;
        r.stage = s.name;
        r.resolution = in.name;
        r.pixels = in.pixels();
        r.threads = t;
        r.bytes_per_pixel = s.bytes_per_pixel;
        Footprint footprint = s.footprint;
        if (s.name == kPanStage) {
          s.run(ws.front(), 0);
          r.bytes_per_pixel = PanTraffic(ws.front());
          // The row reads the same five frames on every call: all of its bytes are fixed.
          footprint = {0, s.frames_per_call * r.bytes_per_pixel};
        }
        // A memcpy of N bytes reads N and writes N: N = traffic / 2 gives the same traffic.
        const auto bytes =
            static_cast<std::size_t>(r.bytes_per_pixel / 2 * static_cast<double>(in.pixels()));
        const std::size_t sources = FloorSources(r.bytes_per_pixel, footprint, in.frames.size(),
                                                 std::numeric_limits<std::size_t>::max());
        for (Workspace& w : ws) w.copy.Ensure(bytes, sources);
        r.floor_sources = ws.front().copy.sources();
        r.footprint_bytes_per_pixel =
            static_cast<double>(in.frames.size()) * footprint.per_frame_bytes +
            footprint.fixed_bytes;
        const Paired p = TimeAgainstFloor(ws, t, s.run, bytes, o.min_time_s);
        r.ns_per_frame = p.stage_ns / s.frames_per_call;
        r.ns_min = p.stage_min / s.frames_per_call;
        r.ns_max = p.stage_max / s.frames_per_call;
        r.memcpy_ns = p.floor_ns;
        r.memcpy_hot_ns = p.hot_floor_ns;
        r.ratio_hot = p.hot_ratio / s.frames_per_call;
        // Per input frame on both sides: a call of a multi-frame stage moves frames_per_call
        // frames' traffic.
        r.ratio = p.ratio / s.frames_per_call;
        r.ratio_min = p.ratio_min / s.frames_per_call;
        r.ratio_max = p.ratio_max / s.frames_per_call;
        if (t > 1) r.note = "2 frames concurrently";
        rows.push_back(r);
      }
    }
    if (!o.skip_recording && !stages_only) {
      const std::filesystem::path dir = std::filesystem::temp_directory_path();
      RecordingOptions def;
      RecordingOptions raw;
      raw.compression_level = 0;
      raw.flush_each_frame = false;
      for (const auto& [label, ro] : {std::pair{"default: deflate 4, flush", def},
                                      std::pair{"uncompressed, no flush", raw}}) {
        const auto [wns, rns] = TimeRecording(in, dir, ro);
        // Frame with truth: 3 x 2 registers + 4 truth distance + 2 causes + 4 sigma bytes.
        rows.push_back({std::string("recording write (") + label + ")", in.name, in.pixels(), 1,
                        wns, 0, 0, "HDF5 to " + dir.string()});
        rows.push_back({std::string("recording read (") + label + ")", in.name, in.pixels(), 1, rns,
                        0, 0, "HDF5 from " + dir.string()});
      }
    }
  }

  std::vector<SimRow> sim_rows;
  if (!o.skip_simulator && !o.peers_only && !stages_only) {
    progress("simulator");
    const double t = std::max(o.min_time_s * 4, 1.0);
    for (int th : thread_counts) {
      sim_rows.push_back(
          SimulatorFps("SR-2 pavilion, moving camera, 2x2 supersampling, all effects",
                       bench::MovingPavilion(), sim::ResolveCameraModel("sr2"), th, t));
      sim_rows.push_back(SimulatorFps("SR-2 pavilion, static camera",
                                      sim::LoadBuiltinScene("pavilion"),
                                      sim::ResolveCameraModel("sr2"), th, t));
      sim_rows.push_back(SimulatorFps("generic 640x480 model, pavilion, moving camera",
                                      bench::MovingPavilion(),
                                      sim::ResolveCameraModel("generic640x480"), th, t));
      // The same two moving cameras with the planar shortcut (SimulatorOptions).
      sim_rows.push_back(SimulatorFps("SR-2 pavilion, moving camera, planar shortcut",
                                      bench::MovingPavilion(), sim::ResolveCameraModel("sr2"), th,
                                      t, true));
      sim_rows.push_back(SimulatorFps("generic 640x480 model, pavilion, moving, planar shortcut",
                                      bench::MovingPavilion(),
                                      sim::ResolveCameraModel("generic640x480"), th, t, true));
    }
  }

  if (!o.export_peers_dir.empty()) {
    progress("exporting clouds for the peer comparison to " + o.export_peers_dir);
    json peers;
    peers["bad_error_m"] = 0.05;
    // The exposure a running robot would have: the may-incremental controller's settled
    // register, not the benchmark's fixed (under-exposed) 40.
    std::vector<int> trajectory;
    const int reg = SettledRegister(200, trajectory);
    progress("may-incremental controller settles at register " + std::to_string(reg));
    peers["integration_register"] = reg;
    peers["controller"] = "may-incremental";
    peers["controller_trajectory"] = trajectory;
    peers["delta_l_scale"] = delta_l_scale;
    std::vector<Input> peer_inputs;
    for (const auto& [w, h] : all_sizes) {
      if (w * h > 640 * 480) continue;  // peers take seconds per megapixel frame
      peer_inputs.push_back(MakeInput(w, h, o.frames, delta_l_scale, reg));
    }
    ExportPeers(peer_inputs, o.export_peers_dir, o.min_time_s, peers);
    if (o.peers_only) {
      std::printf("peer clouds and tofcam filter results in %s (exposure: register %d)\n",
                  o.export_peers_dir.c_str(), reg);
      return;
    }
  }

  if (o.json_output) {
    json jr = json::array();
    for (const Row& r : rows) {
      json j = {{"stage", r.stage},
                {"resolution", r.resolution},
                {"pixels", r.pixels},
                {"threads", r.threads},
                {"us_per_frame", r.ns_per_frame * 1e-3},
                {"ns_per_pixel", r.ns_per_frame / static_cast<double>(r.pixels)},
                {"frames_per_s", 1e9 / r.ns_per_frame}};
      if (r.bytes_per_pixel > 0) {
        j["us_per_frame_min"] = r.ns_min * 1e-3;
        j["us_per_frame_max"] = r.ns_max * 1e-3;
        j["traffic_bytes_per_pixel"] = r.bytes_per_pixel;
        j["memcpy_us"] = r.memcpy_ns * 1e-3;
        j["ratio_to_memcpy"] = r.ratio;  // median of the rounds
        j["ratio_min"] = r.ratio_min;
        j["ratio_max"] = r.ratio_max;
        j["memcpy_sources"] = r.floor_sources;
        if (r.footprint_bytes_per_pixel > 0) {
          j["footprint_bytes_per_pixel"] = r.footprint_bytes_per_pixel;
        }
        j["memcpy_hot_us"] = r.memcpy_hot_ns * 1e-3;
        j["ratio_to_hot_memcpy"] = r.ratio_hot;
      }
      if (!r.note.empty()) j["note"] = r.note;
      jr.push_back(j);
    }
    report["stages"] = jr;
    json js = json::array();
    for (const SimRow& s : sim_rows) {
      js.push_back({{"scene", s.name},
                    {"threads", s.threads},
                    {"frames_per_s", s.frames_per_s},
                    {"frames_per_s_min", s.fps_min},
                    {"frames_per_s_max", s.fps_max}});
    }
    report["simulator"] = js;
    std::printf("%s\n", report.dump(2).c_str());
    return;
  }

  std::printf("tofcam bench  (%s; %s; %d simulated frames per resolution, seed 7)\n",
              report["machine"].get<std::string>().c_str(), __VERSION__, o.frames);
  for (const auto& [k, v] : report["memory_bandwidth_gb_s"].items()) {
    std::printf("memory bandwidth (256 MiB memcpy, read + write), %s: %.1f GB/s\n", k.c_str(),
                v.get<double>());
  }
  std::string last;
  for (const Row& r : rows) {
    if (r.resolution != last) {
      last = r.resolution;
      std::printf("\n== %s (%lld px)\n%-40s %3s %11s %8s %10s %11s %7s %13s %10s %4s\n",
                  r.resolution.c_str(), static_cast<long long>(r.pixels), "stage", "thr",
                  "us/frame", "ns/px", "frames/s", "memcpy us", "ratio", "ratio min-max",
                  "hot ratio", "src");
    }
    std::printf("%-40s %3d %11.1f %8.2f %10.0f", r.stage.c_str(), r.threads, r.ns_per_frame * 1e-3,
                r.ns_per_frame / static_cast<double>(r.pixels), 1e9 / r.ns_per_frame);
    if (r.bytes_per_pixel > 0) {
      std::printf(" %11.1f %7.2f %6.2f-%-6.2f %10.2f %4zu\n", r.memcpy_ns * 1e-3, r.ratio,
                  r.ratio_min, r.ratio_max, r.ratio_hot, r.floor_sources);
    } else {
      std::printf(" %11s %7s\n", "-", "-");
    }
  }
  std::printf(
      "\n2-thread rows: two frames processed concurrently (no stage has a threaded path);\n"
      "time is wall time per frame. memcpy: a copy with the stage's minimal memory "
      "traffic,\ncycling through as many sources (src) as keep its bytes within the stage's own "
      "over the\nframes (one, the hot floor, where a row states no footprint or a second one "
      "would pass it);\nratio: median over %d rounds of back-to-back batches (stage, then memcpy "
      "and hot memcpy\nin turns) of stage / memcpy; hot ratio: the same against one source "
      "copied again and again.\n",
      kRounds);
  if (!sim_rows.empty()) {
    std::printf(
        "\n== simulator (SimulatedCamera::Grab), median of 5 batches\n%-60s %3s %10s %15s\n",
        "scene", "thr", "frames/s", "min-max");
    for (const SimRow& s : sim_rows) {
      std::printf("%-60s %3d %10.1f %7.1f-%-7.1f\n", s.name.c_str(), s.threads, s.frames_per_s,
                  s.fps_min, s.fps_max);
    }
  }
}

void SetupBenchCommand(CLI::App& app) {
  auto opts = std::make_shared<BenchOptions>();
  CLI::App* sub =
      app.add_subcommand("bench",
                         "Time every pipeline stage and the simulator on simulated frames (see "
                         "docs/benchmarks.md)");
  sub->add_flag("--json", opts->json_output, "Print JSON instead of the table");
  sub->add_option("--frames", opts->frames, "Simulated frames per resolution, 1..1000")
      ->capture_default_str();
  sub->add_option("--threads", opts->threads, "1 or 2 only (default: both)");
  sub->add_option("--min-time-s", opts->min_time_s, "Measuring time per figure, s (0, 60]")
      ->capture_default_str();
  sub->add_option("--export-peers", opts->export_peers_dir,
                  "Also write clouds and tofcam filter results for bench/peers to this folder");
  sub->add_option("--stage", opts->stage_filters,
                  "Only the stage rows whose name contains this text, any case (repeatable; "
                  "leaves out the bandwidth, recording and simulator rows)");
  sub->add_option("--size", opts->sizes,
                  "Only this frame size: 160x124, 640x480 or 1024x1024 (repeatable; default: all)");
  sub->add_flag("--no-simulator", opts->skip_simulator, "Skip the simulator frames/s");
  sub->add_flag("--no-recording", opts->skip_recording, "Skip the recording write/read");
  sub->add_flag("--peers-only", opts->peers_only,
                "With --export-peers: only the peer export (no stage timings, no simulator)");
  sub->callback([opts] { RunBench(*opts); });
}

TOFCAM_REGISTER_COMMAND("bench", SetupBenchCommand);

}  // namespace
}  // namespace tofcam::cli

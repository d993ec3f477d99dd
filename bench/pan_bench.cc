// Pan-view benchmark: five simulated frames (bench_inputs.h) placed at -60°..60° assembled into
// the 180° cloud and panorama, at SR-2, VGA and 1 megapixel. items/s = input pixels/s.
#include <benchmark/benchmark.h>

#include <vector>

#include "bench_common.h"
#include "tofcam/core/units.h"
#include "tofcam/pan/pan_view.h"

namespace {

std::vector<tofcam::MetricFrame> PanFrames(const tofcam::bench::SimulatedInput& in) {
  std::vector<tofcam::MetricFrame> frames;
  for (int i = 0; i < 5; ++i) {
    tofcam::MetricFrame f = in.ready[static_cast<std::size_t>(i) % in.ready.size()];
    f.info.pan_angle_rad = (-60.0 + 30.0 * i) * tofcam::kPi / 180.0;
    frames.push_back(std::move(f));
  }
  return frames;
}

// A fresh view per call (allocation and page faults included).
void BM_MakePanView(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  const std::vector<tofcam::MetricFrame> frames = PanFrames(in);
  for (auto _ : state) {
    tofcam::PanView view = tofcam::MakePanView(frames, in.rays, {});
    benchmark::DoNotOptimize(view.panorama.data());
  }
  state.SetItemsProcessed(state.iterations() * 5 * state.range(0) * state.range(1));
}
BENCHMARK(BM_MakePanView)->Apply(tofcam::bench::Resolutions)->Unit(benchmark::kMillisecond);

// The view reused from sweep to sweep (MakePanViewInto), as a robot's loop does.
void BM_MakePanViewInto(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  const std::vector<tofcam::MetricFrame> frames = PanFrames(in);
  tofcam::PanView view;
  for (auto _ : state) {
    tofcam::MakePanViewInto(frames, in.rays, {}, view);
    benchmark::DoNotOptimize(view.panorama.data());
  }
  state.SetItemsProcessed(state.iterations() * 5 * state.range(0) * state.range(1));
}
BENCHMARK(BM_MakePanViewInto)->Apply(tofcam::bench::Resolutions)->Unit(benchmark::kMillisecond);

// The VGA frames on strips of other cell sizes (argument: hundredths of a degree): from about one
// point of a frame per cell (0.2°) to about 100 (2°), where the splat's two forms trade.
void BM_MakePanViewIntoStrip(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Simulated(640, 480);
  const std::vector<tofcam::MetricFrame> frames = PanFrames(in);
  tofcam::PanViewOptions o;
  o.resolution_deg = static_cast<double>(state.range(0)) / 100.0;
  tofcam::PanView view;
  for (auto _ : state) {
    tofcam::MakePanViewInto(frames, in.rays, o, view);
    benchmark::DoNotOptimize(view.panorama.data());
  }
  state.SetItemsProcessed(state.iterations() * 5 * 640 * 480);
  // Points of one frame per cell of the strip (the splat's choice, src/pan/pan_view.cc).
  state.counters["frame_points_per_cell"] = 640.0 * 480 / static_cast<double>(view.panorama.size());
}
BENCHMARK(BM_MakePanViewIntoStrip)
    ->Arg(20)
    ->Arg(35)
    ->Arg(50)
    ->Arg(70)
    ->Arg(100)
    ->Arg(200)
    ->Unit(benchmark::kMillisecond);
}  // namespace

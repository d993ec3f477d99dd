// Filter benchmarks on simulated frames (bench_inputs.h): each filter alone and the sets, at
// SR-2, VGA and 1 megapixel, beside a plain copy of one float channel (the memory floor of a
// per-pixel filter). ApplyFiltersInto reuses its output image, as a per-frame loop does.
// items/s = pixels/s.
#include <benchmark/benchmark.h>

#include <string>

#include "bench_common.h"
#include "tofcam/filters/denoise.h"
#include "tofcam/filters/filter_set.h"
#include "tofcam/filters/frame_pair.h"
#include "tofcam/filters/neighbour_prediction.h"
#include "tofcam/filters/spatial_filter.h"
#include "tofcam/filters/uncertainty.h"

namespace {

using tofcam::FilterSetOptions;
using tofcam::Image;
using tofcam::PixelFlags;
using tofcam::bench::Resolutions;

FilterSetOptions Only(const std::string& name) {
  FilterSetOptions o;
  o.saturation_enabled = o.accuracy_enabled = false;
  o.accuracy_enabled = name == "accuracy";
  o.amplitude_enabled = name == "amplitude";
  o.saturation_enabled = name == "saturation";
  o.range_enabled = name == "range";
  o.flying_pixel_enabled = name == "flying_pixel";
  o.jump_edge_enabled = name == "jump_edge";
  o.weingarten_enabled = name == "weingarten";
  return o;
}

FilterSetOptions All() {
  FilterSetOptions o;
  o.range_enabled = o.amplitude_enabled = o.saturation_enabled = o.accuracy_enabled = true;
  o.flying_pixel_enabled = o.jump_edge_enabled = o.weingarten_enabled = true;
  return o;
}

void Run(benchmark::State& state, const FilterSetOptions& o) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  Image<PixelFlags> out;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::ApplyFiltersInto(in.ready[i++ % in.ready.size()], in.rays, o, out);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}

// Floor: copy one float channel (what a per-pixel filter reads and writes, roughly).
void BM_CopyFloor(benchmark::State& state) { tofcam::bench::CopyFloatChannel(state); }
BENCHMARK(BM_CopyFloor)->Apply(Resolutions);

void BM_AccuracyThreshold(benchmark::State& s) { Run(s, Only("accuracy")); }
BENCHMARK(BM_AccuracyThreshold)->Apply(Resolutions);

void BM_AmplitudeThreshold(benchmark::State& s) { Run(s, Only("amplitude")); }
BENCHMARK(BM_AmplitudeThreshold)->Apply(Resolutions);

void BM_Saturation(benchmark::State& s) { Run(s, Only("saturation")); }
BENCHMARK(BM_Saturation)->Apply(Resolutions);

void BM_Range(benchmark::State& s) { Run(s, Only("range")); }
BENCHMARK(BM_Range)->Apply(Resolutions);

void BM_FlyingPixel(benchmark::State& s) { Run(s, Only("flying_pixel")); }
BENCHMARK(BM_FlyingPixel)->Apply(Resolutions);

void BM_JumpEdge(benchmark::State& s) { Run(s, Only("jump_edge")); }
BENCHMARK(BM_JumpEdge)->Apply(Resolutions);

void BM_WeingartenCell(benchmark::State& s) { Run(s, Only("weingarten")); }
BENCHMARK(BM_WeingartenCell)->Apply(Resolutions);

// The public single-filter form: returns a fresh image per call (allocation included).
void BM_AccuracyThresholdFilterFresh(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  std::size_t i = 0;
  for (auto _ : state) {
    Image<PixelFlags> out = tofcam::AccuracyThresholdFilter(in.ready[i++ % in.ready.size()], {});
    benchmark::DoNotOptimize(out.data());
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_AccuracyThresholdFilterFresh)->Apply(Resolutions);

// The whole set, every filter enabled (issue 7 target: >= 10,000 frames/s at SR-2).
void BM_ApplyAllFilters(benchmark::State& s) { Run(s, All()); }
BENCHMARK(BM_ApplyAllFilters)->Apply(Resolutions);

// The same set as a FilterSet built once for the rays (what Pipeline and a camera loop use):
// without the per-call check of the ray table behind the free function's caches.
void BM_FilterSetAll(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  const tofcam::FilterSet set(All(), in.rays);
  Image<PixelFlags> out;
  std::size_t i = 0;
  for (auto _ : state) {
    set.Process(in.ready[i++ % in.ready.size()], out);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_FilterSetAll)->Apply(Resolutions);

// Everything but the Weingarten cells (the costliest, a baseline rather than a filter to run).
void BM_ApplyAllButCells(benchmark::State& s) {
  FilterSetOptions o = All();
  o.weingarten_enabled = false;
  Run(s, o);
}
BENCHMARK(BM_ApplyAllButCells)->Apply(Resolutions);

// The paper's filters only (defaults: accuracy threshold + saturation).
void BM_ApplyDefaultFilters(benchmark::State& s) { Run(s, FilterSetOptions{}); }
BENCHMARK(BM_ApplyDefaultFilters)->Apply(Resolutions);

// Stages after the filters (not in the paper): edge-preserving smoothing of the distances and
// the combined uncertainty (issue 18), on the same frames.
void RunSmoothing(benchmark::State& state, tofcam::SpatialFilterKind kind) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::SpatialFilterOptions o;
  o.kind = kind;
  Image<float> out;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::SpatialFilterInto(in.ready[i++ % in.ready.size()], o, out);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
void BM_SmoothingMedian(benchmark::State& s) {
  RunSmoothing(s, tofcam::SpatialFilterKind::kMedian);
}
BENCHMARK(BM_SmoothingMedian)->Apply(Resolutions);
void BM_SmoothingBilateral(benchmark::State& s) {
  RunSmoothing(s, tofcam::SpatialFilterKind::kBilateral);
}
BENCHMARK(BM_SmoothingBilateral)->Apply(Resolutions);

// Denoising before the pair (tofcam/filters/denoise.h), its defaults, into reused channels.
void BM_Denoise(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::DenoisedChannels out;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::DenoiseInto(in.ready[i++ % in.ready.size()], {}, out);
    benchmark::DoNotOptimize(out.radial_distance_m.data());
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_Denoise)->Apply(Resolutions);

// The same with a plane fitted to each support (DenoiseOptions::fit_plane).
void BM_DenoisePlane(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::DenoisedChannels out;
  tofcam::DenoiseOptions o;
  o.fit_plane = true;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::DenoiseInto(in.ready[i++ % in.ready.size()], in.rays, o, out);
    benchmark::DoNotOptimize(out.radial_distance_m.data());
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_DenoisePlane)->Apply(Resolutions);

// The neighbours' prediction (tofcam/filters/neighbour_prediction.h), its defaults (7x7), into
// reused images.
void BM_NeighbourPrediction(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::NeighbourPrediction out;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::PredictFromNeighboursInto(in.ready[i++ % in.ready.size()], {}, out);
    benchmark::DoNotOptimize(out.distance_m.data());
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_NeighbourPrediction)->Apply(Resolutions);

// Into a reused image, as a per-frame loop (and Pipeline) runs it.
void BM_Uncertainty(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  std::size_t i = 0;
  Image<PixelFlags> out;
  for (auto _ : state) {
    tofcam::UncertaintyFilterInto(in.ready[i++ % in.ready.size()], {}, out);
    benchmark::DoNotOptimize(out.data());
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_Uncertainty)->Apply(Resolutions);

// The form that returns a fresh image per call (allocation and zero fill included).
void BM_UncertaintyFresh(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  std::size_t i = 0;
  for (auto _ : state) {
    Image<PixelFlags> out = tofcam::UncertaintyFilter(in.ready[i++ % in.ready.size()], {});
    benchmark::DoNotOptimize(out.data());
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_UncertaintyFresh)->Apply(Resolutions);

// Dual-frequency unwrapping of one frame with its predecessor. The simulated frames are all at
// 20 MHz; the second is relabelled 17 MHz, so its distances are read as if wrapped at 8.82 m: the
// combination does the same work per pixel, whatever the pair decides. The combined channels
// are restored from a copy each time (timed with it).
void BM_CombineFramePair(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  const tofcam::MetricFrame& previous = in.ready[0];
  tofcam::MetricFrame current = in.ready[1 % in.ready.size()];
  current.info.modulation_frequency_hz = 17e6;
  tofcam::MetricFrame work = current;
  for (auto _ : state) {
    work.radial_distance_m = current.radial_distance_m;
    work.delta_l_m = current.delta_l_m;
    work.flags = current.flags;
    tofcam::CombineFramePair(previous, work);
    benchmark::DoNotOptimize(work.radial_distance_m.data());
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_CombineFramePair)->Apply(Resolutions);

}  // namespace

// Filter benchmarks: each filter alone and the full set, at SR-2, VGA and 1 megapixel, beside a
// plain copy of the bytes a per-pixel filter reads and writes (the memory-bandwidth floor).
// items/s = pixels/s.
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "bench_common.h"
#include "tofcam/filters/filter_set.h"

namespace {

using tofcam::CameraIntrinsics;
using tofcam::FilterSetOptions;
using tofcam::Image;
using tofcam::MetricFrame;
using tofcam::PixelFlags;
using tofcam::RayTable;

using tofcam::bench::Resolutions;

// SR-2 optics scaled to the requested size (same field of view).
CameraIntrinsics Intrinsics(int w, int h) {
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  k.fx_px *= w / 160.0;
  k.fy_px *= h / 124.0;
  k.width = w;
  k.height = h;
  k.cx_px = (w - 1) / 2.0;
  k.cy_px = (h - 1) / 2.0;
  return k;
}

// Deterministic scene: a tilted wall at ~4 m, a box face at 1.5 m, a little hash noise.
struct Input {
  RayTable rays;
  MetricFrame frame;
};
Input MakeInput(int w, int h) {
  Input in{tofcam::MakeRayTable(Intrinsics(w, h)), {}};
  MetricFrame& f = in.frame;
  f.radial_distance_m = Image<float>(w, h);
  f.amplitude = Image<float>(w, h);
  f.intensity = Image<float>(w, h);
  f.delta_l_m = Image<float>(w, h);
  f.flags = Image<PixelFlags>(w, h);
  std::uint32_t seed = 12345;
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const double rx = in.rays.x(r, c), ry = in.rays.y(r, c), rz = in.rays.z(r, c);
      double d = -4.0 / (0.2 * rx - 0.1 * ry - rz);
      const double t = 1.5 / rz;
      if (t * rx > -0.3 && t * rx < 0.2 && t * ry > -0.2 && t * ry < 0.3) d = t;
      seed = seed * 1664525u + 1013904223u;
      d += 0.01 * ((seed >> 8) / 16777216.0 - 0.5);
      f.radial_distance_m(r, c) = static_cast<float>(d);
      f.amplitude(r, c) = static_cast<float>(20000.0 / (d * d));
      f.intensity(r, c) = static_cast<float>(5000.0 + 20000.0 / (d * d));
      f.delta_l_m(r, c) = static_cast<float>(0.05 * d / 3.0);
    }
  }
  return in;
}

template <typename Fn>
void Run(benchmark::State& state, Fn&& fn) {
  const Input in = MakeInput(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  for (auto _ : state) {
    Image<PixelFlags> out = fn(in);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * state.range(0) * state.range(1));
}

// Floor: copy one float channel and write one flags image (what a per-pixel filter touches).
void BM_CopyFloor(benchmark::State& state) { tofcam::bench::CopyFloatChannel(state); }
BENCHMARK(BM_CopyFloor)->Apply(Resolutions);

void BM_AccuracyThreshold(benchmark::State& s) {
  Run(s, [](const Input& in) { return tofcam::AccuracyThresholdFilter(in.frame, {}); });
}
BENCHMARK(BM_AccuracyThreshold)->Apply(Resolutions);

void BM_AmplitudeThreshold(benchmark::State& s) {
  Run(s, [](const Input& in) { return tofcam::AmplitudeThresholdFilter(in.frame, {}); });
}
BENCHMARK(BM_AmplitudeThreshold)->Apply(Resolutions);

void BM_Saturation(benchmark::State& s) {
  Run(s, [](const Input& in) { return tofcam::SaturationFilter(in.frame, {}); });
}
BENCHMARK(BM_Saturation)->Apply(Resolutions);

void BM_Range(benchmark::State& s) {
  Run(s, [](const Input& in) { return tofcam::RangeFilter(in.frame, {}); });
}
BENCHMARK(BM_Range)->Apply(Resolutions);

void BM_FlyingPixel(benchmark::State& s) {
  Run(s, [](const Input& in) { return tofcam::FlyingPixelFilter(in.frame, {}); });
}
BENCHMARK(BM_FlyingPixel)->Apply(Resolutions);

void BM_JumpEdge(benchmark::State& s) {
  Run(s, [](const Input& in) { return tofcam::JumpEdgeFilter(in.frame, in.rays, {}); });
}
BENCHMARK(BM_JumpEdge)->Apply(Resolutions);

void BM_WeingartenCell(benchmark::State& s) {
  Run(s, [](const Input& in) { return tofcam::WeingartenCellFilter(in.frame, in.rays, {}); });
}
BENCHMARK(BM_WeingartenCell)->Apply(Resolutions);

// The whole set, every filter enabled.
void BM_ApplyAllFilters(benchmark::State& s) {
  FilterSetOptions o;
  o.range_enabled = o.amplitude_enabled = o.saturation_enabled = o.accuracy_enabled = true;
  o.flying_pixel_enabled = o.jump_edge_enabled = o.weingarten_enabled = true;
  Run(s, [&](const Input& in) { return tofcam::ApplyFilters(in.frame, in.rays, o); });
}
BENCHMARK(BM_ApplyAllFilters)->Apply(Resolutions);

// Everything but the Weingarten cells (the costliest, a baseline rather than a filter to run).
void BM_ApplyAllButCells(benchmark::State& s) {
  FilterSetOptions o;
  o.range_enabled = o.amplitude_enabled = o.saturation_enabled = o.accuracy_enabled = true;
  o.flying_pixel_enabled = o.jump_edge_enabled = true;
  Run(s, [&](const Input& in) { return tofcam::ApplyFilters(in.frame, in.rays, o); });
}
BENCHMARK(BM_ApplyAllButCells)->Apply(Resolutions);

// The paper's filters only (defaults: accuracy threshold + saturation).
void BM_ApplyDefaultFilters(benchmark::State& s) {
  Run(s, [](const Input& in) { return tofcam::ApplyFilters(in.frame, in.rays, {}); });
}
BENCHMARK(BM_ApplyDefaultFilters)->Apply(Resolutions);

}  // namespace

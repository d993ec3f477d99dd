// False-colour benchmarks at SR-2, VGA and 1 megapixel beside a plain copy of the bytes
// (distance in, RGB out). items/s = pixels/s.
#include <benchmark/benchmark.h>

#include <cstring>
#include <vector>

#include "bench_common.h"
#include "tofcam/color/false_color.h"

namespace {

using tofcam::Image;
using tofcam::MetricFrame;
using tofcam::PixelFlags;

using tofcam::bench::Resolutions;

// A distance ramp over [0.5, 7] m with every 10th pixel rejected.
MetricFrame MakeFrame(int w, int h) {
  MetricFrame f;
  f.radial_distance_m = Image<float>(w, h);
  f.amplitude = Image<float>(w, h);
  f.flags = Image<PixelFlags>(w, h);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const float d = 0.5f + 6.5f * static_cast<float>(c) / static_cast<float>(w);
      f.radial_distance_m(r, c) = d;
      f.amplitude(r, c) = 20000.0f / (d * d);
      if ((r * w + c) % 10 == 0) f.flags(r, c) = tofcam::Flag::kHighDeltaL;
    }
  }
  return f;
}

// Reads 4 bytes and writes 4 per pixel: a little more than false colour's 4 in, 3 out.
void BM_CopyFloor(benchmark::State& state) { tofcam::bench::CopyFloatChannel(state); }
BENCHMARK(BM_CopyFloor)->Apply(Resolutions);

void BM_FalseColor(benchmark::State& state) {
  const MetricFrame f =
      MakeFrame(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  for (auto _ : state) {
    Image<tofcam::Rgb8> img = tofcam::FalseColor(f, {});
    benchmark::DoNotOptimize(img.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0) * state.range(1));
}
BENCHMARK(BM_FalseColor)->Apply(Resolutions);

void BM_FalseColorShaded(benchmark::State& state) {
  const MetricFrame f =
      MakeFrame(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  tofcam::FalseColorOptions o;
  o.amplitude_shading = true;
  for (auto _ : state) {
    Image<tofcam::Rgb8> img = tofcam::FalseColor(f, o);
    benchmark::DoNotOptimize(img.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0) * state.range(1));
}
BENCHMARK(BM_FalseColorShaded)->Apply(Resolutions);

void BM_AddLegend(benchmark::State& state) {
  const Image<tofcam::Rgb8> img(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  for (auto _ : state) {
    Image<tofcam::Rgb8> out = tofcam::AddLegend(img, 0.0, 7.5);
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0) * state.range(1));
}
BENCHMARK(BM_AddLegend)->Args({160, 124});

}  // namespace

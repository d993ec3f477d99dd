// False-colour benchmarks at SR-2, VGA and 1 megapixel beside a plain copy of the bytes
// (distance in, RGB out). items/s = pixels/s.
#include <benchmark/benchmark.h>

#include <cstring>
#include <vector>

#include "tofcam/color/false_color.h"

namespace {

using tofcam::Image;
using tofcam::MetricFrame;
using tofcam::PixelFlags;

void Resolutions(benchmark::internal::Benchmark* b) {
  b->Args({160, 124})->Args({640, 480})->Args({1024, 1024});
}

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

void BM_CopyFloor(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0) * state.range(1));
  // Reads 4 bytes and writes 4 per pixel: a little more than false colour's 4 in, 3 out.
  std::vector<float> src(n, 1.0f), dst(n);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), n * sizeof(float));
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(n));
}
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

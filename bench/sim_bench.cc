// Simulator throughput: frames per second of SimulatedCamera::Grab() (items_per_second). The
// second argument, where there is one, switches the planar shortcut on (1) or off (0).
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "noise.h"
#include "sim_scenes.h"
#include "tofcam/sim/simulated_camera.h"

namespace {

using tofcam::bench::MovingPavilion;
using tofcam::bench::PanningPavilion;
using tofcam::sim::CameraModel;
using tofcam::sim::LoadBuiltinScene;
using tofcam::sim::ResolveCameraModel;
using tofcam::sim::Scene;
using tofcam::sim::SimulatedCamera;
using tofcam::sim::SimulatorOptions;

void Run(benchmark::State& state, Scene scene, const CameraModel& model, int threads,
         bool shortcut = false) {
  SimulatorOptions o;
  o.threads = threads;
  o.planar_shortcut = shortcut;
  o.integration_time_register = 40;
  SimulatedCamera cam(std::move(scene), model, o);
  for (auto _ : state) {
    auto frame = cam.Grab();
    benchmark::DoNotOptimize(frame);
  }
  state.SetItemsProcessed(state.iterations());
}

void BM_PavilionMovingCamera(benchmark::State& state) {
  Run(state, MovingPavilion(), ResolveCameraModel("sr2"), static_cast<int>(state.range(0)),
      state.range(1) != 0);
}
BENCHMARK(BM_PavilionMovingCamera)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

void BM_PavilionFastPan(benchmark::State& state) {
  Run(state, PanningPavilion(), ResolveCameraModel("sr2"), static_cast<int>(state.range(0)),
      state.range(1) != 0);
}
BENCHMARK(BM_PavilionFastPan)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

void BM_PavilionStaticCamera(benchmark::State& state) {
  Run(state, LoadBuiltinScene("pavilion"), ResolveCameraModel("sr2"),
      static_cast<int>(state.range(0)), state.range(1) != 0);
}
BENCHMARK(BM_PavilionStaticCamera)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

void BM_Generic640MovingCamera(benchmark::State& state) {
  Run(state, MovingPavilion(), ResolveCameraModel("generic640x480"),
      static_cast<int>(state.range(0)), state.range(1) != 0);
}
BENCHMARK(BM_Generic640MovingCamera)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

void BM_DemoSequence(benchmark::State& state) {
  Run(state, LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), 1, state.range(0) != 0);
}
BENCHMARK(BM_DemoSequence)->Arg(0)->Arg(1)->UseRealTime()->Unit(benchmark::kMillisecond);

// The tap noise alone (src/sim/noise.h): eight rows of 640 pixels with means of a lit scene
// (2,000-60,000 electrons, Gaussian regime) and read noise, drawn row by row (argument 0, the
// portable NoisyTaps) or eight streams at once (1, NoisyTapsRows: the AVX-512 form where the CPU
// has it). Items: pixels.
void BM_NoisyTaps(benchmark::State& state) {
  constexpr int kRows = 8, kWidth = 640;
  const std::size_t n = static_cast<std::size_t>(kRows) * kWidth;
  std::vector<double> mu[4];
  std::vector<float> sd[4], out[4];
  for (int k = 0; k < 4; ++k) {
    mu[k].resize(n);
    sd[k].resize(n);
    out[k].resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      mu[k][i] = 2000.0 + 58000.0 * static_cast<double>((i * 7919 + k * 104729) % 1000) / 1000.0;
      sd[k][i] = static_cast<float>(std::sqrt(mu[k][i]));
    }
  }
  const double* const mu_p[4] = {mu[0].data(), mu[1].data(), mu[2].data(), mu[3].data()};
  const float* const sd_p[4] = {sd[0].data(), sd[1].data(), sd[2].data(), sd[3].data()};
  float* taps[kRows][4];
  std::uint64_t seeds[kRows];
  for (int j = 0; j < kRows; ++j) {
    seeds[j] = tofcam::sim::internal::RowSeed(7, j);
    for (int k = 0; k < 4; ++k) taps[j][k] = out[k].data() + static_cast<std::size_t>(j) * kWidth;
  }
  const bool rows_at_once = state.range(0) != 0;
  for (auto _ : state) {
    if (rows_at_once) {
      tofcam::sim::internal::NoisyTapsRows(kRows, kWidth, kWidth, seeds, true, 30.0, mu_p, sd_p,
                                           taps);
    } else {
      for (int j = 0; j < kRows; ++j) {
        const std::size_t at = static_cast<std::size_t>(j) * kWidth;
        const double* const mu_j[4] = {mu_p[0] + at, mu_p[1] + at, mu_p[2] + at, mu_p[3] + at};
        const float* const sd_j[4] = {sd_p[0] + at, sd_p[1] + at, sd_p[2] + at, sd_p[3] + at};
        tofcam::sim::internal::NoisyTaps(kWidth, seeds[j], true, 30.0, mu_j, sd_j, taps[j]);
      }
    }
    benchmark::DoNotOptimize(out[0].data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(n));
}
BENCHMARK(BM_NoisyTaps)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

}  // namespace

// Pan-view benchmark: five SR-2 frames at -60°..60° assembled into the 180° cloud and panorama.
// items/s = input pixels/s.
#include <benchmark/benchmark.h>

#include <vector>

#include "tofcam/core/units.h"
#include "tofcam/pan/pan_view.h"

namespace {

void BM_MakePanView(benchmark::State& state) {
  const tofcam::CameraIntrinsics k = tofcam::CameraIntrinsics::SwissRangerSr2();
  const tofcam::RayTable rays = tofcam::MakeRayTable(k);
  std::vector<tofcam::MetricFrame> frames;
  for (int i = 0; i < 5; ++i) {
    tofcam::MetricFrame f;
    f.radial_distance_m = tofcam::Image<float>(k.width, k.height);
    f.amplitude = tofcam::Image<float>(k.width, k.height, 3000.0f);
    f.flags = tofcam::Image<tofcam::PixelFlags>(k.width, k.height);
    for (int r = 0; r < k.height; ++r)
      for (int c = 0; c < k.width; ++c) f.radial_distance_m(r, c) = 2.0f + 0.01f * (r + c + i);
    f.info.pan_angle_rad = (-60.0 + 30.0 * i) * tofcam::kPi / 180.0;
    frames.push_back(std::move(f));
  }
  for (auto _ : state) {
    tofcam::PanView view = tofcam::MakePanView(frames, rays, {});
    benchmark::DoNotOptimize(view.panorama.data());
  }
  state.SetItemsProcessed(state.iterations() * 5 * k.width * k.height);
}
BENCHMARK(BM_MakePanView);

}  // namespace

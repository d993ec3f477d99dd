// Point-cloud benchmarks: MakePointCloud at SR-2, VGA and 1 megapixel beside a plain copy of the
// same bytes (the memory-bandwidth floor), plus PLY / PCD writing of an SR-2 cloud.
// items/s = pixels/s.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <vector>

#include "bench_common.h"
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/io/cloud_io.h"

namespace {

using tofcam::Image;
using tofcam::MetricFrame;
using tofcam::PixelFlags;

using tofcam::bench::Resolutions;

tofcam::CameraIntrinsics Intrinsics(int w, int h) {
  tofcam::CameraIntrinsics k = tofcam::CameraIntrinsics::SwissRangerSr2();
  k.fx_px *= w / 160.0;
  k.fy_px *= h / 124.0;
  k.width = w;
  k.height = h;
  k.cx_px = (w - 1) / 2.0;
  k.cy_px = (h - 1) / 2.0;
  return k;
}

// A tilted wall with a box face in front; every 10th pixel rejected.
MetricFrame MakeFrame(const tofcam::RayTable& rays) {
  const int w = rays.x.width(), h = rays.x.height();
  MetricFrame f;
  f.radial_distance_m = Image<float>(w, h);
  f.amplitude = Image<float>(w, h);
  f.intensity = Image<float>(w, h);
  f.delta_l_m = Image<float>(w, h);
  f.flags = Image<PixelFlags>(w, h);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const double rx = rays.x(r, c), ry = rays.y(r, c), rz = rays.z(r, c);
      double d = -4.0 / (0.2 * rx - 0.1 * ry - rz);
      const double t = 1.5 / rz;
      if (t * rx > -0.3 && t * rx < 0.2 && t * ry > -0.2 && t * ry < 0.3) d = t;
      f.radial_distance_m(r, c) = static_cast<float>(d);
      f.amplitude(r, c) = static_cast<float>(20000.0 / (d * d));
      f.intensity(r, c) = static_cast<float>(5000.0 + 20000.0 / (d * d));
      f.delta_l_m(r, c) = 0.02f;
      if ((r * w + c) % 10 == 0) f.flags(r, c) = tofcam::Flag::kHighDeltaL;
    }
  }
  return f;
}

// Floor: the bytes MakePointCloud moves (reads distance, 3 rays, amplitude, intensity, ΔL,
// flags; writes 6 floats and flags), as plain memcpy of 6 float arrays plus flags.
void BM_CopyFloor(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0) * state.range(1));
  std::vector<float> src(6 * n, 1.0f), dst(6 * n);
  std::vector<std::uint16_t> fs(n), fd(n);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), src.size() * sizeof(float));
    std::memcpy(fd.data(), fs.data(), n * sizeof(std::uint16_t));
    benchmark::DoNotOptimize(dst.data());
    benchmark::DoNotOptimize(fd.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(n));
}
BENCHMARK(BM_CopyFloor)->Apply(Resolutions);

void BM_MakePointCloud(benchmark::State& state) {
  const tofcam::RayTable rays = tofcam::MakeRayTable(
      Intrinsics(static_cast<int>(state.range(0)), static_cast<int>(state.range(1))));
  const MetricFrame f = MakeFrame(rays);
  for (auto _ : state) {
    tofcam::PointCloud cloud = tofcam::MakePointCloud(f, rays);
    benchmark::DoNotOptimize(cloud.x.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * state.range(0) * state.range(1));
}
BENCHMARK(BM_MakePointCloud)->Apply(Resolutions);

// The per-frame form: the cloud's storage is reused (no allocation, no page faults).
void BM_MakePointCloudInto(benchmark::State& state) {
  const tofcam::RayTable rays = tofcam::MakeRayTable(
      Intrinsics(static_cast<int>(state.range(0)), static_cast<int>(state.range(1))));
  const MetricFrame f = MakeFrame(rays);
  tofcam::PointCloud cloud;
  for (auto _ : state) {
    tofcam::MakePointCloudInto(f, rays, cloud);
    benchmark::DoNotOptimize(cloud.x.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * state.range(0) * state.range(1));
}
BENCHMARK(BM_MakePointCloudInto)->Apply(Resolutions);

std::filesystem::path Scratch(const char* name) {
  return std::filesystem::temp_directory_path() /
         (std::string("tofcam_cloud_bench_") + std::to_string(::getpid()) + name);
}

// File writers at SR-2 size (includes fsync of the atomic write).
void BM_WritePlyBinary(benchmark::State& state) {
  const tofcam::RayTable rays = tofcam::MakeRayTable(Intrinsics(160, 124));
  const tofcam::PointCloud cloud = tofcam::MakePointCloud(MakeFrame(rays), rays);
  const auto path = Scratch(".ply");
  for (auto _ : state) tofcam::WritePly(path, cloud, tofcam::PlyFormat::kBinary, false);
  std::filesystem::remove(path);
  state.SetItemsProcessed(state.iterations() * 160 * 124);
}
BENCHMARK(BM_WritePlyBinary);

void BM_WritePcd(benchmark::State& state) {
  const tofcam::RayTable rays = tofcam::MakeRayTable(Intrinsics(160, 124));
  const tofcam::PointCloud cloud = tofcam::MakePointCloud(MakeFrame(rays), rays);
  const auto path = Scratch(".pcd");
  for (auto _ : state) tofcam::WritePcd(path, cloud, false);
  std::filesystem::remove(path);
  state.SetItemsProcessed(state.iterations() * 160 * 124);
}
BENCHMARK(BM_WritePcd);

}  // namespace

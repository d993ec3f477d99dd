// Recording and importer throughput. Recordings go to the temporary directory (a tmpfs or disk:
// flush cost depends on it).
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>
#include <random>
#include <sstream>
#include <string>

#include "tofcam/core/atomic_file.h"
#include "tofcam/io/importers.h"
#include "tofcam/io/recording.h"

namespace tofcam {
namespace {

namespace fs = std::filesystem;

fs::path TempFile(const char* name) {
  return fs::temp_directory_path() / ("tofcam_io_bench_" + std::to_string(::getpid()) + name);
}

// An SR-2 sized frame (160 x 124) with noisy registers, so compression sees realistic entropy.
Frame NoisyFrame() {
  const CameraInfo cam;
  Frame f;
  f.distance = Image<std::uint16_t>(cam.width(), cam.height());
  f.amplitude = Image<std::uint16_t>(cam.width(), cam.height());
  f.intensity = Image<std::uint16_t>(cam.width(), cam.height());
  std::mt19937 rng(1);
  std::normal_distribution<double> noise(0.0, 40.0);
  for (std::size_t i = 0; i < f.distance.size(); ++i) {
    f.distance[i] = static_cast<std::uint16_t>(20000 + i % 160 * 30 + noise(rng));
    f.amplitude[i] = static_cast<std::uint16_t>(3000 + noise(rng));
    f.intensity[i] = static_cast<std::uint16_t>(9000 + noise(rng));
  }
  f.info.camera_model = cam.model;
  return f;
}

// Arguments: compression level, flush after each frame (0/1).
void BM_RecordingAppend(benchmark::State& state) {
  const fs::path file = TempFile("_append.h5");
  RecordingOptions options;
  options.compression_level = static_cast<int>(state.range(0));
  options.flush_each_frame = state.range(1) != 0;
  Frame frame = NoisyFrame();
  {
    RecordingWriter writer(file, CameraInfo{}, options);
    for (auto _ : state) {
      writer.Append(frame);
      ++frame.info.sequence;
      frame.info.timestamp_ns += 33'000'000;
    }
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["bytes_per_frame"] =
      static_cast<double>(fs::file_size(file)) / static_cast<double>(state.iterations());
  fs::remove(file);
}
BENCHMARK(BM_RecordingAppend)
    ->Args({0, 1})
    ->Args({4, 1})
    ->Args({4, 0})
    ->Unit(benchmark::kMicrosecond);

void BM_RecordingRead(benchmark::State& state) {
  const fs::path file = TempFile("_read.h5");
  {
    RecordingWriter writer(file, CameraInfo{});
    const Frame frame = NoisyFrame();
    for (int i = 0; i < 64; ++i) writer.Append(frame);
  }
  const RecordingReader reader(file);
  std::size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(reader.Read(i++ % 64));
  state.SetItemsProcessed(state.iterations());
  fs::remove(file);
}
BENCHMARK(BM_RecordingRead)->Unit(benchmark::kMicrosecond);

void BM_ImportAdiInterleaved(benchmark::State& state) {
  const std::string bytes =
      ReadFile(fs::path(TOFCAM_SOURCE_DIR) / "tests/data/real/adi_adtf3175/frame_mode3.bin");
  for (auto _ : state) {
    benchmark::DoNotOptimize(ParseAdiInterleaved(bytes, 512, 512, "frame_mode3.bin"));
  }
  state.SetItemsProcessed(state.iterations() * 512 * 512);
}
BENCHMARK(BM_ImportAdiInterleaved)->Unit(benchmark::kMillisecond);

void BM_ParseMesaDat(benchmark::State& state) {
  std::ostringstream out;
  for (int s = 0; s < 5; ++s) {
    out << "% section\n";
    for (int r = 0; r < 144; ++r) {
      for (int c = 0; c < 176; ++c) out << (s == 0 ? 2.0 + 0.001 * c : 0.5) << ' ';
      out << '\n';
    }
  }
  out << "% timestamp: 0\n";
  const std::string text = out.str();
  for (auto _ : state) benchmark::DoNotOptimize(ParseMesaDat(text, "bench.dat"));
  state.SetItemsProcessed(state.iterations());
  state.SetBytesProcessed(state.iterations() * static_cast<long long>(text.size()));
}
BENCHMARK(BM_ParseMesaDat)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace tofcam

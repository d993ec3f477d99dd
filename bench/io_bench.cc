// Recording and importer throughput. Recordings go to the temporary directory (a tmpfs or disk:
// flush cost depends on it).
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>
#include <sstream>
#include <string>

#include "bench_common.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/io/importers.h"
#include "tofcam/io/recording.h"

namespace tofcam {
namespace {

namespace fs = std::filesystem;

fs::path TempFile(const char* name) {
  return fs::temp_directory_path() / ("tofcam_io_bench_" + std::to_string(::getpid()) + name);
}

// Arguments: width, height, compression level, flush after each frame (0/1). Simulated frames
// (bench_inputs.h) with their ground truth, as `tofcam record` writes them.
void BM_RecordingAppend(benchmark::State& state) {
  const bench::SimulatedInput& in = bench::Input(state);
  const fs::path file = TempFile("_append.h5");
  RecordingOptions options;
  options.compression_level = static_cast<int>(state.range(2));
  options.flush_each_frame = state.range(3) != 0;
  {
    RecordingWriter writer(file, in.info, options);
    std::size_t i = 0;
    for (auto _ : state) {
      Frame frame = in.frames[i % in.frames.size()];
      frame.info.sequence = i;
      frame.info.timestamp_ns = static_cast<std::int64_t>(i) * 33'000'000;
      ++i;
      writer.Append(frame);
    }
  }
  bench::SetPixels(state);
  state.counters["bytes_per_frame"] =
      static_cast<double>(fs::file_size(file)) / static_cast<double>(state.iterations());
  fs::remove(file);
}
BENCHMARK(BM_RecordingAppend)
    ->ArgNames({"w", "h", "deflate", "flush"})
    ->Args({160, 124, 0, 1})
    ->Args({160, 124, 4, 1})
    ->Args({160, 124, 4, 0})
    ->Args({640, 480, 4, 1})
    ->Args({640, 480, 0, 0})
    ->Args({1024, 1024, 4, 1})
    ->Args({1024, 1024, 0, 0})
    ->Unit(benchmark::kMicrosecond);

void BM_RecordingRead(benchmark::State& state) {
  const bench::SimulatedInput& in = bench::Input(state);
  const fs::path file = TempFile("_read.h5");
  {
    RecordingWriter writer(file, in.info);
    for (std::size_t i = 0; i < 16; ++i) {
      Frame frame = in.frames[i % in.frames.size()];
      frame.info.sequence = i;
      frame.info.timestamp_ns = static_cast<std::int64_t>(i) * 33'000'000;
      writer.Append(frame);
    }
  }
  const RecordingReader reader(file);
  std::size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(reader.Read(i++ % 16));
  bench::SetPixels(state);
  fs::remove(file);
}
BENCHMARK(BM_RecordingRead)->Apply(bench::Resolutions)->Unit(benchmark::kMicrosecond);

// The importers parse real cameras' file formats: their input is those files (test data), not
// the simulator.
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

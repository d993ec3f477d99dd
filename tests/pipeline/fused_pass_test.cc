// The per-pixel pass of PaperChain and Pipeline::Process against the stage functions called one
// after the other on the whole frame: the expectation is that composition, and the results must
// agree bit for bit (the same loops, run chunk by chunk into reused buffers).
#include "pipeline/fused_pass.h"  // internal: the chunk switch (src/pipeline)

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

#include "../filters/test_scene.h"
#include "pipeline/stage_kernels.h"  // internal: kernels::kCacheChunkPixels
#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/control/integration_time_controller.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/filters/filter_set.h"
#include "tofcam/pipeline/frame_stats.h"
#include "tofcam/pipeline/metric_conversion.h"
#include "tofcam/pipeline/paper_chain.h"
#include "tofcam/pipeline/pipeline.h"

namespace tofcam {
namespace {

constexpr std::size_t kWholeFrame = std::numeric_limits<std::size_t>::max();

// The fused pass runs frames without a streamed cloud in chunks of `pixels` (0: the CPU's
// choice, pipeline_internal::CacheChunkPixels) while the guard lives.
class ForcedChunk {
 public:
  explicit ForcedChunk(std::size_t pixels) { pipeline_internal::ForceCacheChunkForTesting(pixels); }
  ~ForcedChunk() { pipeline_internal::ForceCacheChunkForTesting(0); }
  ForcedChunk(const ForcedChunk&) = delete;
  ForcedChunk& operator=(const ForcedChunk&) = delete;
};

// SR-2 optics scaled to w x h (odd sizes leave partial blocks and vector tails).
CameraInfo Camera(int w, int h) {
  CameraInfo info;
  CameraIntrinsics& k = info.intrinsics;
  k = CameraIntrinsics::SwissRangerSr2();
  k.fx_px *= w / 160.0;
  k.fy_px *= h / 124.0;
  k.width = w;
  k.height = h;
  k.cx_px = (w - 1) / 2.0;
  k.cy_px = (h - 1) / 2.0;
  info.model = "SR-2";
  info.modulation_frequency_hz = 20e6;
  info.min_integration_register = 1;
  info.max_integration_register = 255;
  return info;
}

// Register frame of the filter test scene (wall + box) with deterministic noise, some pixels
// without amplitude, some saturated, and source flags on a few.
Frame SceneFrame(const CameraInfo& info, std::uint32_t seed, bool with_intensity = true) {
  const test::Scene scene = test::MakeScene(info.intrinsics);
  const int w = info.width(), h = info.height();
  const double range = UnambiguousRangeM(info.modulation_frequency_hz);
  Frame f;
  f.distance = Image<std::uint16_t>(w, h);
  f.amplitude = Image<std::uint16_t>(w, h);
  f.intensity = Image<std::uint16_t>(w, h);
  f.source_flags = Image<PixelFlags>(w, h);
  auto next = [&seed] {
    seed = seed * 1664525u + 1013904223u;
    return (seed >> 8) / 16777216.0;
  };
  for (std::size_t i = 0; i < f.distance.size(); ++i) {
    const double d = scene.frame.radial_distance_m[i] + 0.2 * (next() - 0.5) * (next() < 0.1);
    f.distance[i] = static_cast<std::uint16_t>(std::fmod(d, range) / range * 65536.0);
    const double a = next() < 0.03 ? 0.0 : scene.frame.amplitude[i] * (0.2 + next());
    f.amplitude[i] = static_cast<std::uint16_t>(std::min(a, 65532.0));
    f.intensity[i] = static_cast<std::uint16_t>(
        next() < 0.02 ? 65532.0 : std::min(65532.0, scene.frame.intensity[i] * (0.5 + next())));
    if (next() < 0.01) f.source_flags[i] = PixelFlags(Flag::kSaturated);
  }
  f.info.modulation_frequency_hz = info.modulation_frequency_hz;
  f.info.integration_time_register = 40;
  f.info.integration_time_us = 40 * 255.0;
  f.info.distance_offset_register = 123;
  f.info.camera_model = info.model;
  f.info.has_intensity = with_intensity;
  if (!with_intensity) f.intensity = Image<std::uint16_t>(w, h);
  return f;
}

OffsetCalibration Calibration(const CameraInfo& info, bool with_table) {
  OffsetCalibration c;
  c.camera_model = info.model;
  c.width = info.width();
  c.height = info.height();
  c.modulation_frequency_hz = info.modulation_frequency_hz;
  c.integration_time_us = 20 * 255.0;
  c.exposure_offset_m_per_ms = 0.0005;
  c.offset_m = Image<float>(c.width, c.height);
  c.pixel_flags = Image<PixelFlags>(c.width, c.height);
  for (std::size_t i = 0; i < c.offset_m.size(); ++i) {
    c.offset_m[i] = 0.001f * static_cast<float>(i % 97) - 0.05f;
    if (i % 211 == 0) c.pixel_flags[i] = PixelFlags(Flag::kInvalid);
  }
  if (with_table) {
    DistanceCorrection g;
    g.start_m = 0.3;
    g.step_m = 0.05;
    for (int k = 0; k < 150; ++k) g.correction_m.push_back(0.02f * std::sin(0.2f * k));
    c.distance_correction = g;
  }
  return c;
}

// Bitwise (NaN-safe); empty containers (no data pointer) compare equal.
template <typename T>
void ExpectSameBits(const std::vector<T>& a, const std::vector<T>& b, const char* what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  if (a.empty()) return;
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(T)), 0) << what;
}

template <typename T>
void ExpectSameBits(const Image<T>& a, const Image<T>& b, const char* what) {
  ASSERT_TRUE(a.SameSize(b)) << what;
  if (a.empty()) return;
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(T)), 0) << what;
}

void ExpectSameFrame(const MetricFrame& a, const MetricFrame& b) {
  ExpectSameBits(a.radial_distance_m, b.radial_distance_m, "distance");
  ExpectSameBits(a.amplitude, b.amplitude, "amplitude");
  ExpectSameBits(a.intensity, b.intensity, "intensity");
  ExpectSameBits(a.delta_l_m, b.delta_l_m, "delta_l_m");
  ExpectSameBits(a.flags, b.flags, "flags");
}

void ExpectSameCloud(const PointCloud& a, const PointCloud& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  ExpectSameBits(a.x, b.x, "x");
  ExpectSameBits(a.y, b.y, "y");
  ExpectSameBits(a.z, b.z, "z");
  ExpectSameBits(a.amplitude, b.amplitude, "cloud amplitude");
  ExpectSameBits(a.intensity, b.intensity, "cloud intensity");
  ExpectSameBits(a.delta_l_m, b.delta_l_m, "cloud delta_l_m");
  ExpectSameBits(a.flags, b.flags, "cloud flags");
}

// The per-pixel thresholds' two kernel entries agree for every set: ORing into flags that hold
// other bits gives those bits | what the writing entry writes (the fused pass ORs, FilterSet
// writes). An odd span length runs the loops' tails; a missing intensity reads as zeros.
TEST(PixelFilterKernelsTest, OringEqualsWritingThenOring) {
  test::Scene s = test::MakeScene();
  MetricFrame& f = s.frame;
  for (std::size_t i = 0; i < f.radial_distance_m.size(); i += 11) f.amplitude[i] = 300.0f;
  for (std::size_t i = 5; i < f.radial_distance_m.size(); i += 13) f.delta_l_m[i] = 0.5f;
  for (std::size_t i = 7; i < f.radial_distance_m.size(); i += 17) f.intensity[i] = 65532.0f;
  for (std::size_t i = 3; i < f.radial_distance_m.size(); i += 19) f.radial_distance_m[i] = 9.0f;
  for (std::size_t i = 9; i < f.radial_distance_m.size(); i += 23) f.amplitude[i] = 65532.0f;
  constexpr std::size_t kSpan = 19'837;  // odd, and short of the frame's 19,840 pixels
  for (const bool with_intensity : {true, false}) {
    for (unsigned set = 1; set < 16; ++set) {
      const FilterSetOptions o = test::ThresholdSet(set);
      const kernels::PixelFilterPlan plan = kernels::PreparePixelFilters(f, o);
      const float* in = with_intensity ? f.intensity.data() : nullptr;
      std::vector<PixelFlags> written(kSpan, PixelFlags(static_cast<std::uint16_t>(0xFFFF)));
      kernels::PixelFiltersSpan(plan, kSpan, f.radial_distance_m.data(), f.amplitude.data(), in,
                                f.delta_l_m.data(), written.data());
      std::vector<PixelFlags> ored(kSpan);
      for (std::size_t i = 0; i < kSpan; ++i) {
        ored[i] = PixelFlags(static_cast<std::uint16_t>(i * 2654435761u >> 20));
      }
      const std::vector<PixelFlags> prior = ored;
      kernels::PixelFiltersOrSpan(plan, kSpan, f.radial_distance_m.data(), f.amplitude.data(), in,
                                  f.delta_l_m.data(), ored.data());
      std::size_t raised = 0;
      for (std::size_t i = 0; i < kSpan; ++i) {
        ASSERT_EQ(ored[i].bits(), (prior[i] | written[i]).bits()) << "set " << set << " at " << i;
        raised += written[i].None() ? 0 : 1;
      }
      EXPECT_GT(raised, 0u) << "set " << set;
      EXPECT_LT(raised, kSpan) << "set " << set;
    }
  }
}

TEST(PaperChainTest, EqualsTheStagesCalledOneByOne) {
  // Frames without a streamed cloud run whole or in chunks, by CPU (CacheChunkPixels); each is
  // run here in every form: whole, in chunks of kernels::kCacheChunkPixels (1024: 31 x 17 in one
  // partial chunk, 700 x 3 in two and a partial one, 157 x 123 ending in a chunk of 879 pixels,
  // not a multiple of 16) and in chunks of 7 (every chunk a tail for the vector loops).
  // 1100 x 960 pixels: a cloud large enough to be streamed (kernels::kStreamCloudBytes), so the
  // pass runs in chunks of 2^14 pixels (64 and a partial one) whatever the CPU.
  for (const auto& [w, h] : {std::pair{160, 124}, std::pair{157, 123}, std::pair{31, 17},
                             std::pair{700, 3}, std::pair{1100, 960}}) {
    for (const std::size_t chunk : {kWholeFrame, kernels::kCacheChunkPixels, std::size_t{7}}) {
      if (w == 1100 && chunk != kWholeFrame) continue;
      const ForcedChunk forced(chunk);
      for (const bool table : {false, true}) {
        for (const bool intensity : {true, false}) {
          SCOPED_TRACE(std::to_string(w) + "x" + std::to_string(h) + (table ? " table" : "") +
                       (intensity ? "" : " no intensity") + " chunk " + std::to_string(chunk));
          const CameraInfo info = Camera(w, h);
          PaperChainOptions o;
          o.calibration = Calibration(info, table);
          o.threshold.max_delta_l_m = 0.05;
          PaperChain chain(o, info);
          MetricFrame out;
          PointCloud cloud;
          for (std::uint32_t seed : {1u, 2u}) {  // the second frame reuses the buffers
            const Frame f = SceneFrame(info, seed, intensity);
            chain.Process(f, out, cloud);
            MetricFrame m;
            ConvertToMetricInto(f, {}, m);
            ApplyCalibrationInPlace(m, *o.calibration);
            ComputeDeltaLInto(m, o.accuracy, m.delta_l_m);
            MergeFlags(m, AccuracyThresholdFilter(m, o.threshold));
            const PointCloud expected = MakePointCloud(m, chain.rays(), o.cloud);
            ExpectSameFrame(out, m);
            ExpectSameCloud(cloud, expected);
            std::size_t high = 0;
            for (PixelFlags p : m.flags.pixels()) high += p.Has(Flag::kHighDeltaL) ? 1 : 0;
            EXPECT_GT(high, 0u);
            EXPECT_LT(high, m.flags.size());
          }
        }
      }
    }
  }
}

TEST(PaperChainTest, ReusesItsOutputBuffersAndChecksTheFrame) {
  const CameraInfo info = Camera(160, 124);
  PaperChainOptions o;
  o.calibration = Calibration(info, true);
  PaperChain chain(o, info);
  MetricFrame out;
  PointCloud cloud;
  chain.Process(SceneFrame(info, 1), out, cloud);
  const void* before[] = {out.radial_distance_m.data(), out.delta_l_m.data(), out.flags.data(),
                          cloud.x.data(), cloud.flags.data()};
  chain.Process(SceneFrame(info, 2), out, cloud);
  const void* after[] = {out.radial_distance_m.data(), out.delta_l_m.data(), out.flags.data(),
                         cloud.x.data(), cloud.flags.data()};
  for (int k = 0; k < 5; ++k) EXPECT_EQ(before[k], after[k]) << k;  // no reallocation

  EXPECT_THROW(chain.Process(SceneFrame(Camera(80, 62), 1), out, cloud), Error);
  Frame other = SceneFrame(info, 1);
  other.info.modulation_frequency_hz = 30e6;
  try {
    chain.Process(other, out, cloud);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
  OffsetCalibration wrong = *o.calibration;
  wrong.camera_model = "O3D303";
  o.calibration = wrong;
  EXPECT_THROW(PaperChain(o, info), Error);
}

// What Pipeline::Process did before the fused pass (tofcam 0.1), stage by stage.
PipelineResult ReferenceProcess(const PipelineOptions& o, const RayTable& rays,
                                IntegrationTimeController* controller, const Frame& frame) {
  PipelineResult r;
  MetricFrame& m = r.frame;
  ConvertToMetricInto(frame, o.metric, m);
  if (o.calibration) ApplyCalibrationInPlace(m, *o.calibration);
  if (o.accuracy_enabled) ComputeDeltaLInto(m, o.accuracy, m.delta_l_m);
  r.input_flags = m.flags;
  r.filter_flags = ApplyFilters(m, rays, o.filters);
  MergeFlags(m, r.filter_flags);
  r.next_integration_register =
      controller != nullptr ? controller->Update(m) : m.info.integration_time_register;
  if (o.cloud_enabled) r.cloud = MakePointCloud(m, rays, o.cloud);
  FrameStatsOptions so = o.stats;
  so.intensity_roi = o.controller.roi;
  so.intensity_exclude_flags = o.controller.exclude_flags;
  so.intensity_clipped = o.controller.clipped_intensity;
  r.stats = ComputeFrameStats(m, so);
  return r;
}

TEST(PipelineFusedTest, ProcessEqualsTheStagesCalledOneByOne) {
  // Sets 0-2 in every chunking (PaperChainTest says why), set 3 in the CPU's own (chunk 0).
  for (const auto& [set, chunk] :
       {std::pair{0, kWholeFrame}, std::pair{1, kWholeFrame}, std::pair{2, kWholeFrame},
        std::pair{0, kernels::kCacheChunkPixels}, std::pair{1, kernels::kCacheChunkPixels},
        std::pair{2, kernels::kCacheChunkPixels}, std::pair{0, std::size_t{7}},
        std::pair{1, std::size_t{7}}, std::pair{2, std::size_t{7}}, std::pair{3, std::size_t{0}}}) {
    const ForcedChunk forced(chunk);
    SCOPED_TRACE(std::to_string(set) + " chunk " + std::to_string(chunk));
    // Set 3: the defaults on a larger frame, accuracy off.
    const CameraInfo info = set == 3 ? Camera(1031, 517) : Camera(157, 123);
    PipelineOptions o;
    o.calibration = Calibration(info, true);
    FilterSetOptions& f = o.filters;
    if (set >= 1) f.flying_pixel_enabled = f.jump_edge_enabled = f.weingarten_enabled = true;
    if (set == 1) f.range_enabled = f.amplitude_enabled = true;
    f.range.max_distance_m = 4.0;  // cuts the far part of the tilted wall off
    if (set == 2) f.saturation_enabled = f.accuracy_enabled = false;
    if (set == 3) o.accuracy_enabled = f.accuracy_enabled = false;
    Pipeline pipeline(o, info);
    std::unique_ptr<IntegrationTimeController> controller =
        MakeController(pipeline.options().controller);
    PipelineResult result;
    for (std::uint32_t seed : {3u, 4u, 5u}) {
      const Frame frame = SceneFrame(info, seed);
      pipeline.Process(frame, result);
      const PipelineResult expected =
          ReferenceProcess(pipeline.options(), pipeline.rays(), controller.get(), frame);
      ExpectSameFrame(result.frame, expected.frame);
      ExpectSameBits(result.input_flags, expected.input_flags, "input flags");
      ExpectSameBits(result.filter_flags, expected.filter_flags, "filter flags");
      ExpectSameCloud(result.cloud, expected.cloud);
      EXPECT_EQ(result.next_integration_register, expected.next_integration_register);
      EXPECT_EQ(result.stats.kept_pixels, expected.stats.kept_pixels);
      auto same = [](double x, double y) { return (std::isnan(x) && std::isnan(y)) || x == y; };
      EXPECT_TRUE(same(result.stats.mean_intensity, expected.stats.mean_intensity));
      EXPECT_TRUE(same(result.stats.mean_delta_l_m, expected.stats.mean_delta_l_m));
      if (set == 1) {  // not vacuous: every filter fires somewhere, and not everywhere
        for (Flag flag :
             {Flag::kOutOfRange, Flag::kLowAmplitude, Flag::kSaturated, Flag::kHighDeltaL,
              Flag::kFlyingPixel, Flag::kJumpEdge, Flag::kSparseCell}) {
          std::size_t count = 0;
          for (PixelFlags p : expected.filter_flags.pixels()) count += p.Has(flag) ? 1 : 0;
          EXPECT_GT(count, 0u) << FlagName(flag);
          EXPECT_LT(count, expected.filter_flags.size()) << FlagName(flag);
        }
      }
    }
  }
}

TEST(PipelineFusedTest, SteadyLoopKeepsItsBuffers) {
  const CameraInfo info = Camera(160, 124);
  PipelineOptions o;
  o.calibration = Calibration(info, true);
  o.filters.flying_pixel_enabled = o.filters.jump_edge_enabled = true;
  Pipeline pipeline(o, info);
  PipelineResult r;
  pipeline.Process(SceneFrame(info, 1), r);
  auto pointers = [&r] {
    return std::vector<const void*>{r.frame.radial_distance_m.data(),
                                    r.frame.amplitude.data(),
                                    r.frame.intensity.data(),
                                    r.frame.delta_l_m.data(),
                                    r.frame.flags.data(),
                                    r.input_flags.data(),
                                    r.filter_flags.data(),
                                    r.cloud.x.data(),
                                    r.cloud.delta_l_m.data(),
                                    r.cloud.flags.data()};
  };
  const std::vector<const void*> before = pointers();
  for (std::uint32_t seed = 2; seed < 5; ++seed) pipeline.Process(SceneFrame(info, seed), r);
  EXPECT_EQ(pointers(), before);
}

}  // namespace
}  // namespace tofcam

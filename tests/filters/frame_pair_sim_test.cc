// Dual-frequency unwrapping and single-frequency wrap detection on the simulated SR-2 looking at
// a wall past its 20 MHz range (scenes/beyond-range.yaml), against the ground truth.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/core/error.h"
#include "tofcam/filters/frame_pair.h"
#include "tofcam/pipeline/pipeline.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam {
namespace {

// The simulated SR-2 at register 60 on `scene`, with a second frequency (17 MHz) when `dual`.
std::unique_ptr<sim::SimulatedCamera> Camera(const std::string& scene, bool dual,
                                             std::uint64_t seed) {
  sim::CameraModel model = sim::ResolveCameraModel("sr2");
  if (dual) model.modulation_frequencies_hz = {20e6, 17e6};
  sim::SimulatorOptions so;
  so.seed = seed;
  auto camera = std::make_unique<sim::SimulatedCamera>(sim::LoadBuiltinScene(scene), model, so);
  camera->SetIntegrationTimeRegister(60);
  return camera;
}

// No controller, no accuracy threshold: the tests judge unwrapping and wrap detection alone.
// ΔL in metres of this camera's σ, the scale its ground truth gives (as `tofcam run` does on a
// simulator): the consistency test needs σ, and eq. 2 as printed overstates it ~5x.
PipelineOptions Unfiltered(const std::string& scene) {
  PipelineOptions po;
  po.controller_enabled = false;
  po.filters.accuracy_enabled = false;
  if (const auto scale =
          GroundTruthNoiseScale(ConvertToMetric(*Camera(scene, false, 99)->Grab()))) {
    po.accuracy.scale = *scale;
  }
  return po;
}

TEST(FramePairSim, TwoFrequenciesReadAWallBeyondTheRange) {
  const auto camera = Camera("beyond-range", true, 4);
  Pipeline pipeline(Unfiltered("beyond-range"), camera->Info());
  FramePairCombiner combiner;
  int right = 0, wrong = 0, inconsistent = 0, single_right = 0, single_total = 0;
  for (int k = 0; k < 6; ++k) {
    camera->SetModulationFrequencyHz(k % 2 == 0 ? 20e6 : 17e6);
    PipelineResult r = pipeline.Process(*camera->Grab());
    MetricFrame& m = r.frame;
    for (std::size_t i = 0; i < m.flags.size(); ++i) {
      if (m.flags[i].Any(kRejectMask)) continue;
      ++single_total;
      if (std::abs(m.radial_distance_m[i] - m.truth->radial_distance_m[i]) < 0.1) ++single_right;
    }
    if (!combiner.Process(m)) continue;
    for (std::size_t i = 0; i < m.flags.size(); ++i) {
      if (m.flags[i].Has(Flag::kInconsistent)) {
        ++inconsistent;
        continue;
      }
      if (m.flags[i].Any(kRejectMask)) continue;
      // A wrong pair of wrap counts is off by at least |L(17 MHz) - L(20 MHz)| = 1.32 m; the
      // noise of this dim wall is ~5-10 cm per frame. Half of 1.32 m separates the two.
      const double e = std::abs(m.radial_distance_m[i] - m.truth->radial_distance_m[i]);
      (e < 0.66 ? right : wrong)++;
    }
  }
  std::printf("single frequency: %d of %d within 10 cm; two: %d right, %d wrong, %d inconsistent\n",
              single_right, single_total, right, wrong, inconsistent);
  // The wall is at 9 m and more: one frequency reads none of it right; two unwrap nearly all
  // (the dim corners' σ is too large to tell the wrap counts apart: they are flagged
  // ambiguous, kInconsistent), and a wrong pair that passes is rare.
  EXPECT_EQ(single_right, 0);
  EXPECT_GT(right, 0.98 * (right + wrong + inconsistent));
  EXPECT_LT(wrong, 0.001 * (right + wrong));
}

TEST(FramePairSim, PipelineAlternatesFrequenciesAndUnwraps) {
  // The pipeline's own loop: it asks for 17 MHz after a 20 MHz frame and back, and combines.
  const auto camera = Camera("beyond-range", true, 6);
  PipelineOptions po = Unfiltered("beyond-range");
  po.frame_pair_enabled = true;
  po.alternate_modulation_frequency_hz = 17e6;
  Pipeline pipeline(po, camera->Info());
  PipelineResult r;
  std::vector<double> frequencies;
  int right = 0, total = 0;
  for (int k = 0; k < 5; ++k) {
    pipeline.Process(*camera->Grab(), r);
    frequencies.push_back(r.frame.info.modulation_frequency_hz);
    camera->SetModulationFrequencyHz(r.next_modulation_frequency_hz);
    EXPECT_EQ(r.combined, k > 0);
    if (!r.combined) continue;
    for (std::size_t i = 0; i < r.frame.flags.size(); ++i) {
      if (r.frame.flags[i].Any(kRejectMask)) continue;
      ++total;
      const bool ok =
          std::abs(r.frame.radial_distance_m[i] - r.frame.truth->radial_distance_m[i]) < 0.66;
      right += ok;
      // The cloud follows the unwrapped distance (the wall is at 9 m and beyond).
      if (ok) {
        EXPECT_GT(r.cloud.z[i], 7.0f) << i;
      }
    }
  }
  EXPECT_EQ(frequencies, (std::vector<double>{20e6, 17e6, 20e6, 17e6, 20e6}));
  EXPECT_GT(right, 0.99 * total);
  po.accuracy_enabled = false;
  EXPECT_THROW(Pipeline(po, camera->Info()), Error);
}

TEST(FramePairSim, WrapCheckOnOneFrequency) {
  // Pixels the truth marks kBeyondUnambiguous: how many the amplitude check flags (recall), and
  // how many others it flags (false alarms). Reported for scenes that mix near and far surfaces;
  // a scene of nothing but one wrapped wall is its own brightest surface, so the check (relative
  // to the frame's envelope) cannot see it: asserted as a known blind spot.
  for (const std::string scene : {"corridor", "beyond-range", "wall"}) {
    const auto camera = Camera(scene, false, 5);
    Pipeline pipeline(Unfiltered(scene), camera->Info());
    const PipelineResult r = pipeline.Process(*camera->Grab());
    const Image<PixelFlags> f = WrapCheckFilter(r.frame, pipeline.rays());
    int wrapped = 0, caught = 0, others = 0, alarms = 0;
    for (std::size_t i = 0; i < f.size(); ++i) {
      if (r.frame.flags[i].Any(kRejectMask)) continue;
      const bool beyond = r.frame.truth->causes[i].Has(Flag::kBeyondUnambiguous);
      const bool flagged = f[i].Has(Flag::kInconsistent);
      if (beyond) {
        ++wrapped;
        caught += flagged;
      } else {
        ++others;
        alarms += flagged;
      }
    }
    std::printf("%s: %d of %d wrapped pixels flagged, %d of %d others\n", scene.c_str(), caught,
                wrapped, alarms, others);
    if (scene == "wall") {
      EXPECT_EQ(wrapped, 0);
    }
    if (scene == "wall") {
      EXPECT_LT(alarms, 0.01 * others);  // one near wall: nothing is too dark for its distance
    }
    if (scene == "corridor") {
      // Measured 96 % caught and 15 % false alarms. Amplitude cannot tell a surface of albedo
      // rho at d from one of rho ((d + L) / d)^2 at d + L: the false alarms are the corridor's
      // dark floor and far walls near L. The bounds (90 %, 20 %) document that trade-off; the
      // way out is a second frequency (the test above).
      ASSERT_GT(wrapped, 100);
      EXPECT_GT(caught, 0.9 * wrapped);
      EXPECT_LT(alarms, 0.2 * others);
    }
  }
}

}  // namespace
}  // namespace tofcam

// The combined uncertainty (noise plus edges) against the truth on every built-in scene: does
// one threshold in metres separate pixels within 5 cm of the truth from the others better than
// the paper's ΔL threshold? A prediction, measured here; nothing was tuned to it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/filters/uncertainty.h"
#include "tofcam/pipeline/pipeline.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam {
namespace {

struct Counts {
  long long tp = 0, fp = 0, fn = 0;
  void Add(bool rejected, bool bad) {
    if (rejected && bad) ++tp;
    if (rejected && !bad) ++fp;
    if (!rejected && bad) ++fn;
  }
  [[nodiscard]] double F1() const { return 2.0 * tp / (2.0 * tp + fp + fn); }
};

TEST(UncertaintySim, OneThresholdOnEveryBuiltinScene) {
  Counts paper, combined;
  for (const std::string& scene : sim::BuiltinSceneNames()) {
    sim::SimulatorOptions so;
    so.seed = 21;
    sim::SimulatedCamera camera(sim::LoadBuiltinScene(scene), sim::ResolveCameraModel("sr2"), so);
    PipelineOptions po;
    po.controller_enabled = false;
    Frame frame = *camera.Grab();
    // ΔL in metres of this camera: the scale its ground truth gives (as `tofcam run` does).
    const std::optional<double> scale = GroundTruthNoiseScale(ConvertToMetric(frame));
    if (scale) po.accuracy.scale = *scale;
    Pipeline pipeline(po, camera.Info());
    const PipelineResult r = pipeline.Process(frame);
    const MetricFrame& m = r.frame;
    const Image<PixelFlags> extra = UncertaintyFilter(m);
    for (std::size_t i = 0; i < m.flags.size(); ++i) {
      const float truth = m.truth->radial_distance_m[i];
      const bool bad = !std::isfinite(truth) ||
                       !(std::abs(m.radial_distance_m[i] - truth) <= 0.05) ||
                       m.truth->causes[i].Has(Flag::kNoReturn);
      const bool paper_rejects = m.flags[i].Any(kRejectMask);
      paper.Add(paper_rejects, bad);
      combined.Add(paper_rejects || extra[i].Any(kRejectMask), bad);
    }
  }
  std::printf("F1 at 5 cm over the built-in scenes: paper's filters %.3f, + uncertainty %.3f\n",
              paper.F1(), combined.F1());
  EXPECT_GT(combined.F1(), paper.F1());
}

TEST(UncertaintySim, PipelineStageEqualsTheFilter) {
  sim::SimulatedCamera camera(sim::LoadBuiltinScene("hand"), sim::ResolveCameraModel("sr2"), {});
  const Frame frame = *camera.Grab();
  PipelineOptions po;
  po.controller_enabled = false;
  Pipeline plain(po, camera.Info());
  po.uncertainty_enabled = true;
  Pipeline with(po, camera.Info());
  const PipelineResult a = plain.Process(frame), b = with.Process(frame);
  const Image<PixelFlags> raised = UncertaintyFilter(a.frame);
  int flagged = 0;
  for (std::size_t i = 0; i < raised.size(); ++i) {
    EXPECT_EQ(b.frame.flags[i], a.frame.flags[i] | raised[i]) << i;
    flagged += raised[i].Has(Flag::kLowConfidence);
    if (raised[i].Any(kRejectMask)) {
      EXPECT_TRUE(std::isnan(b.cloud.z[i]));  // the cloud follows
    }
  }
  EXPECT_GT(flagged, 0);
}

}  // namespace
}  // namespace tofcam

#include "bench_inputs.h"

#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <utility>

#include "sim_scenes.h"
#include "tofcam/accuracy/delta_l.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/pipeline/metric_conversion.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::bench {
namespace {

std::unique_ptr<SimulatedInput> Make(int width, int height) {
  auto in = std::make_unique<SimulatedInput>();
  sim::SimulatorOptions so;
  so.seed = 7;
  so.threads = 2;  // generating the inputs is not what is measured
  so.integration_time_register = 40;
  sim::SimulatedCamera cam(MovingPavilion(),
                           sim::WithResolution(sim::ResolveCameraModel("sr2"), width, height), so);
  in->info = cam.Info();
  in->rays = MakeRayTable(in->info.intrinsics);
  OffsetCalibration& c = in->calibration;
  c.camera_model = in->info.model;
  c.width = width;
  c.height = height;
  c.modulation_frequency_hz = in->info.modulation_frequency_hz;
  c.offset_m = cam.FixedPatternOffsetM();
  DistanceCorrection g;
  g.start_m = 0.3;
  g.step_m = 0.05;
  for (int k = 0; k < 150; ++k) {
    g.correction_m.push_back(static_cast<float>(0.03 * std::sin(k * 0.05 * 4 * kPi / 7.5)));
  }
  c.distance_correction = g;
  c.Validate();
  for (int i = 0; i < kFrames; ++i) {
    std::optional<Frame> f = cam.Grab();
    if (!f) throw Error(ErrorCode::kInternal, "simulator returned no frame");
    MetricFrame m = ConvertToMetric(*f);
    ApplyCalibrationInPlace(m, c);
    ComputeDeltaLInto(m, {}, m.delta_l_m);
    Frame bare = *f;
    bare.truth.reset();
    in->frames.push_back(std::move(*f));
    in->camera_frames.push_back(std::move(bare));
    in->ready.push_back(std::move(m));
  }
  return in;
}

}  // namespace

const SimulatedInput& Simulated(int width, int height) {
  static std::mutex mutex;
  static std::map<std::pair<int, int>, std::unique_ptr<SimulatedInput>> cache;
  const std::lock_guard<std::mutex> lock(mutex);
  std::unique_ptr<SimulatedInput>& slot = cache[{width, height}];
  if (!slot) slot = Make(width, height);
  return *slot;
}

}  // namespace tofcam::bench

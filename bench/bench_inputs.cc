#include "bench_inputs.h"

#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <utility>

#include "bench_calibration.h"
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
  // Fitted once per process: every size has the SR-2 pixel.
  static const double scale = FitBenchNoiseScale();
  in->accuracy.scale = scale;
  OffsetCalibration& c = in->calibration;
  c = SimulatorOffsets(cam);
  c.distance_correction = MadeUpDistanceTable();
  c.Validate();
  for (int i = 0; i < kFrames; ++i) {
    std::optional<Frame> f = cam.Grab();
    if (!f) throw Error(ErrorCode::kInternal, "simulator returned no frame");
    MetricFrame m = ConvertToMetric(*f);
    ApplyCalibrationInPlace(m, c);
    ComputeDeltaLInto(m, in->accuracy, m.delta_l_m);
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

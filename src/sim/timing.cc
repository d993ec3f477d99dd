#include "timing.h"

#include <cmath>

#include "geometry.h"
#include "tofcam/core/units.h"

namespace tofcam::sim::internal {

RenderKey MakeRenderKey(const Scene& scene, const std::vector<char>& dynamic, double time_s,
                        double pan_rad) {
  RenderKey key;
  key.camera = CameraPose(scene, time_s, pan_rad).matrix().topRows<3>();
  for (std::size_t i = 0; i < scene.objects.size(); ++i) {
    if (!dynamic[i]) continue;
    const Eigen::Matrix<double, 3, 4> m = scene.objects[i].motion.At(time_s).matrix().topRows<3>();
    key.objects.insert(key.objects.end(), m.data(), m.data() + 12);
  }
  for (const Lamp& l : scene.lamps) key.lamps.push_back(l.OnAt(time_s) ? 1 : 0);
  key.valid = true;
  return key;
}

bool PoseMoved(const Eigen::Matrix<double, 3, 4>& x, const Eigen::Matrix<double, 3, 4>& y,
               double threshold_m) {
  const double lever = 5.0;  // m: rotation error measured at a 5 m lever arm
  // ||R1 - R2||_F = 2 sqrt(2) sin(angle / 2), about sqrt(2) * angle for small angles.
  return (x.col(3) - y.col(3)).norm() +
             lever * (x.leftCols<3>() - y.leftCols<3>()).norm() / std::sqrt(2.0) >
         threshold_m;
}

bool MovesDuringExposure(const RenderKey& a, const RenderKey& b, double threshold_m) {
  bool split = PoseMoved(a.camera, b.camera, threshold_m);
  for (std::size_t i = 0; !split && i + 12 <= a.objects.size(); i += 12) {
    split = PoseMoved(Eigen::Map<const Eigen::Matrix<double, 3, 4>>(&a.objects[i]),
                      Eigen::Map<const Eigen::Matrix<double, 3, 4>>(&b.objects[i]), threshold_m);
  }
  return split;
}

double PanAngleAtRad(const std::vector<PanKey>& sched, double t) {
  if (sched.empty()) return 0.0;
  if (t <= sched.front().time_s) return sched.front().angle_deg * kPi / 180;
  if (t >= sched.back().time_s) return sched.back().angle_deg * kPi / 180;
  for (std::size_t i = 1; i < sched.size(); ++i) {
    if (t < sched[i].time_s) {
      const double w = (t - sched[i - 1].time_s) / (sched[i].time_s - sched[i - 1].time_s);
      return (sched[i - 1].angle_deg + w * (sched[i].angle_deg - sched[i - 1].angle_deg)) * kPi /
             180;
    }
  }
  return sched.back().angle_deg * kPi / 180;
}

double FramePeriodS(const CameraModel& model, double t_int_s) {
  return std::max(1.0 / model.max_frame_rate_hz, t_int_s + model.readout_time_us * 1e-6);
}

double WarmupOffsetM(const CameraModel& model, double power_on_time_s, double time_s) {
  return model.warmup_amplitude_m *
         std::exp(-(power_on_time_s + time_s) / model.warmup_time_constant_s);
}

}  // namespace tofcam::sim::internal

#include <cmath>
#include <cstdio>

#include "tofcam/tofcam.h"

int main() {
  const tofcam::CameraIntrinsics k = tofcam::CameraIntrinsics::SwissRangerSr2();
  const tofcam::RayTable rays = tofcam::MakeRayTable(k);
  const double fov_deg = k.HorizontalFovRad() * 180.0 / tofcam::kPi;
  std::printf("consumer: tofcam %s, %dx%d rays, fov %.2f deg\n", tofcam::kVersionString,
              rays.x.width(), rays.x.height(), fov_deg);
  return std::abs(fov_deg - 42.8) < 0.5 ? 0 : 1;
}

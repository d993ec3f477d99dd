#include "tofcam/core/camera_intrinsics.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

void RequireFinite(double value, const char* name) {
  if (!std::isfinite(value)) {
    throw Error(ErrorCode::kInvalidArgument, std::string("intrinsics: ") + name + " is not finite");
  }
}

double AngleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  // atan2 of |a x b| and a.b stays accurate for small and large angles alike.
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

}  // namespace

void NoRay(double u, double v) {
  throw Error(ErrorCode::kInvalidArgument,
              "intrinsics: the distortion cannot be inverted at pixel (" + std::to_string(u) +
                  ", " + std::to_string(v) + "): it has no ray");
}

// A lens model whose distortion folds over inside the image maps two directions to one pixel
// and leaves some pixels without a ray on the first branch (Undistort then fails or lands on
// the fold's far side): the corners alone cannot show it. Along rays from the optical axis in
// 32 directions (and through the four corners), the distortion must stay one to one (positive
// Jacobian, growing distorted radius) out to the largest distorted radius any pixel has.
void RequireUnfoldedDistortion(const CameraIntrinsics& k) {
  if (!k.HasDistortion()) return;
  double rho_max = 0.0;  // distorted normalised radius of the farthest image corner
  std::vector<double> angles;
  for (double u : {-0.5, k.width - 0.5}) {
    for (double v : {-0.5, k.height - 0.5}) {
      const double x = (u - k.cx_px) / k.fx_px, y = (v - k.cy_px) / k.fy_px;
      rho_max = std::max(rho_max, std::hypot(x, y));
      angles.push_back(std::atan2(y, x));
    }
  }
  constexpr int kDirections = 32;
  for (int i = 0; i < kDirections; ++i) angles.push_back(2.0 * M_PI * i / kDirections);
  // Steps of 1/64 of the radius reached so far (at least of rho_max / 64): fine near the axis,
  // and a strongly compressing lens still arrives in a few hundred steps. r = 1e3 is 89.94
  // degrees off the axis.
  constexpr double kMaxRadius = 1e3;
  constexpr double kH = 1e-7;
  for (double a : angles) {
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    double r = 0.0, last_rho = 0.0;
    while (last_rho < rho_max) {
      r += std::max(rho_max, r) / 64.0;
      const Eigen::Vector2d n = r * dir;
      const double rho = k.Distort(n).norm();
      Eigen::Matrix2d j;
      j.col(0) = (k.Distort(n + Eigen::Vector2d(kH, 0)) - k.Distort(n - Eigen::Vector2d(kH, 0))) /
                 (2 * kH);
      j.col(1) = (k.Distort(n + Eigen::Vector2d(0, kH)) - k.Distort(n - Eigen::Vector2d(0, kH))) /
                 (2 * kH);
      if (!(rho > last_rho) || !(j.determinant() > 0.0) || r > kMaxRadius) {
        throw Error(ErrorCode::kInvalidArgument,
                    "intrinsics: the lens distortion (k1..k6, p1, p2) folds over inside the "
                    "image (" +
                        std::to_string(static_cast<int>(std::round(std::atan(r) * 180.0 / M_PI))) +
                        " degrees off the axis): some pixels would have no ray");
      }
      last_rho = rho;
    }
  }
}

CameraIntrinsics CameraIntrinsics::SwissRangerSr2() {
  CameraIntrinsics k;
  k.width = 160;
  k.height = 124;
  k.fx_px = 8.0e-3 / 39.2e-6;
  k.fy_px = 8.0e-3 / 54.8e-6;
  k.cx_px = (k.width - 1) / 2.0;
  k.cy_px = (k.height - 1) / 2.0;
  return k;
}

void CameraIntrinsics::Validate() const {
  if (width <= 0 || height <= 0 ||
      static_cast<long long>(width) * height > Image<float>::kMaxPixels) {
    throw Error(ErrorCode::kInvalidArgument,
                "intrinsics: width and height must be > 0 and the image at most 2^28 pixels");
  }
  for (auto [v, n] : {std::pair{fx_px, "fx_px"},
                      {fy_px, "fy_px"},
                      {cx_px, "cx_px"},
                      {cy_px, "cy_px"},
                      {k1, "k1"},
                      {k2, "k2"},
                      {k3, "k3"},
                      {k4, "k4"},
                      {k5, "k5"},
                      {k6, "k6"},
                      {p1, "p1"},
                      {p2, "p2"}}) {
    RequireFinite(v, n);
  }
  if (fx_px <= 0 || fy_px <= 0) {
    throw Error(ErrorCode::kInvalidArgument, "intrinsics: focal lengths fx_px, fy_px must be > 0");
  }
  // A lens model must at least give the image centre a ray. Its corners need not have one: a
  // wide-angle camera's fitted model may fold beyond its field of view (the Azure Kinect's wide
  // mode at its unlit corners), and those pixels get NaN rays, so no points. A renderer needs
  // every pixel: RequireUnfoldedDistortion.
  if (!Unproject({(width - 1) / 2.0, (height - 1) / 2.0}).allFinite()) {
    throw Error(ErrorCode::kInvalidArgument,
                "intrinsics: the distortion cannot be inverted at the image centre");
  }
}

bool CameraIntrinsics::HasDistortion() const noexcept {
  return k1 != 0 || k2 != 0 || k3 != 0 || k4 != 0 || k5 != 0 || k6 != 0 || p1 != 0 || p2 != 0;
}

Eigen::Vector2d CameraIntrinsics::Distort(const Eigen::Vector2d& n) const noexcept {
  const double x = n.x(), y = n.y();
  const double r2 = x * x + y * y, r4 = r2 * r2, r6 = r4 * r2;
  const double radial = (1 + k1 * r2 + k2 * r4 + k3 * r6) / (1 + k4 * r2 + k5 * r4 + k6 * r6);
  return {x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
          y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y};
}

Eigen::Vector2d CameraIntrinsics::Undistort(const Eigen::Vector2d& d) const noexcept {
  if (!HasDistortion()) return d;
  Eigen::Vector2d n = d;
  constexpr double kStep = 1e-7;
  for (int it = 0; it < 50; ++it) {
    const Eigen::Vector2d r = Distort(n) - d;
    if (r.squaredNorm() < 1e-26) break;
    Eigen::Matrix2d j;
    j.col(0) = (Distort(n + Eigen::Vector2d(kStep, 0)) - Distort(n - Eigen::Vector2d(kStep, 0))) /
               (2 * kStep);
    j.col(1) = (Distort(n + Eigen::Vector2d(0, kStep)) - Distort(n - Eigen::Vector2d(0, kStep))) /
               (2 * kStep);
    const double det = j.determinant();
    if (!std::isfinite(det) || std::abs(det) < 1e-12) break;
    n -= j.inverse() * r;
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (!((Distort(n) - d).squaredNorm() < 1e-20)) return {nan, nan};
  // A root beyond the lens's first fold (where the model, fitted inside the field of view,
  // turns back and rises again) is a direction the camera does not see: no ray, not a wrong
  // one. The first branch keeps a positive Jacobian from the axis out to the root; eight
  // samples along the way find a fold region wider than an eighth of the radius.
  for (int k = 1; k <= 8; ++k) {
    const Eigen::Vector2d m = n * (k / 8.0);
    Eigen::Matrix2d j;
    j.col(0) = (Distort(m + Eigen::Vector2d(kStep, 0)) - Distort(m - Eigen::Vector2d(kStep, 0))) /
               (2 * kStep);
    j.col(1) = (Distort(m + Eigen::Vector2d(0, kStep)) - Distort(m - Eigen::Vector2d(0, kStep))) /
               (2 * kStep);
    if (!(j.determinant() > 0.0)) return {nan, nan};
  }
  return n;
}

Eigen::Vector2d CameraIntrinsics::Project(const Eigen::Vector3d& p) const noexcept {
  if (!(p.z() > 0)) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    return {nan, nan};
  }
  const Eigen::Vector2d d = Distort({p.x() / p.z(), p.y() / p.z()});
  return {fx_px * d.x() + cx_px, fy_px * d.y() + cy_px};
}

Eigen::Vector3d CameraIntrinsics::Unproject(const Eigen::Vector2d& pixel) const noexcept {
  const Eigen::Vector2d n = Undistort({(pixel.x() - cx_px) / fx_px, (pixel.y() - cy_px) / fy_px});
  return Eigen::Vector3d(n.x(), n.y(), 1.0).normalized();
}

double CameraIntrinsics::HorizontalFovRad() const noexcept {
  return AngleBetween(Unproject({-0.5, cy_px}), Unproject({width - 0.5, cy_px}));
}

double CameraIntrinsics::VerticalFovRad() const noexcept {
  return AngleBetween(Unproject({cx_px, -0.5}), Unproject({cx_px, height - 0.5}));
}

RayTable MakeRayTable(const CameraIntrinsics& k) {
  k.Validate();
  RayTable t{Image<float>(k.width, k.height), Image<float>(k.width, k.height),
             Image<float>(k.width, k.height)};
  for (int r = 0; r < k.height; ++r) {
    for (int c = 0; c < k.width; ++c) {
      const Eigen::Vector3d ray = k.Unproject({static_cast<double>(c), static_cast<double>(r)});
      t.x(r, c) = static_cast<float>(ray.x());
      t.y(r, c) = static_cast<float>(ray.y());
      t.z(r, c) = static_cast<float>(ray.z());
    }
  }
  return t;
}

}  // namespace tofcam

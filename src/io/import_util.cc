#include "import_util.h"

#include <cmath>
#include <system_error>

#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam::io_internal {

void CheckImageSize(int width, int height, const std::string& name) {
  if (width <= 0 || height <= 0 || width > 65536 || height > 65536 ||
      static_cast<long long>(width) * height > Image<std::uint16_t>::kMaxPixels) {
    throw Error(
        ErrorCode::kInvalidArgument,
        name + ": invalid image size " + std::to_string(width) + " x " + std::to_string(height));
  }
}

std::string ReadExactly(const std::filesystem::path& file, std::size_t expected_bytes,
                        const std::string& what) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(file, ec);
  if (ec) {
    throw Error(std::filesystem::exists(file) ? ErrorCode::kIo : ErrorCode::kNotFound,
                file.string() + ": cannot open (" + ec.message() + ")");
  }
  if (size != expected_bytes) {
    throw Error(ErrorCode::kFormat, file.string() + ": " + std::to_string(size) +
                                        " bytes, expected " + std::to_string(expected_bytes) +
                                        " (" + what + ")");
  }
  std::string bytes = ReadFile(file, expected_bytes);
  if (bytes.size() != expected_bytes) {
    throw Error(ErrorCode::kFormat, file.string() + ": file changed while reading");
  }
  return bytes;
}

Frame BlankFrame(int width, int height, const std::string& model, double modulation_frequency_hz) {
  Frame f;
  f.distance = Image<std::uint16_t>(width, height);
  f.amplitude = Image<std::uint16_t>(width, height);
  f.intensity = Image<std::uint16_t>(width, height);
  f.source_flags = Image<PixelFlags>(width, height);
  f.info.camera_model = model;
  f.info.modulation_frequency_hz = modulation_frequency_hz;
  f.info.has_intensity = false;
  return f;
}

CameraInfo ImportedCameraInfo(const std::string& model, const CameraIntrinsics& intrinsics,
                              double modulation_frequency_hz) {
  CameraInfo info;
  info.model = model;
  info.intrinsics = intrinsics;
  info.modulation_frequency_hz = modulation_frequency_hz;
  // Imported files have no settable integration time: register 0 means "unknown".
  info.integration_time_step_us = 0.0;
  info.integration_time_base_us = 0.0;
  info.min_integration_register = 0;
  info.max_integration_register = 0;
  info.has_intensity = false;
  info.has_ground_truth = false;
  return info;
}

double FrequencyForRange(double range_m) { return kSpeedOfLightMPerS / (2.0 * range_m); }

void SetDistanceMm(Frame& frame, std::size_t i, double mm, double range_m) {
  const double reg = mm * kDistanceRegisterSpan / (range_m * 1000.0);
  if (!(mm > 0) || !(reg < kDistanceRegisterSpan - 0.5)) {
    frame.distance[i] = 0;
    frame.source_flags[i].Set(Flag::kInvalid);
    return;
  }
  frame.distance[i] = static_cast<std::uint16_t>(std::lround(reg));
}

void SetAmplitude(Frame& frame, std::size_t i, double amplitude) {
  if (!(amplitude >= 0) || !std::isfinite(amplitude)) {
    frame.amplitude[i] = 0;
    frame.source_flags[i].Set(Flag::kInvalid);
    return;
  }
  if (amplitude > kMaxSignalRegister) {
    frame.amplitude[i] = kMaxSignalRegister;
    frame.source_flags[i].Set(Flag::kSaturated);
    return;
  }
  frame.amplitude[i] = static_cast<std::uint16_t>(std::lround(amplitude));
}

namespace {
// Least squares a = s * t + b; returns false when degenerate.
bool FitLine(const std::vector<double>& t, const std::vector<double>& a, double& s, double& b) {
  const double n = static_cast<double>(t.size());
  double st = 0, sa = 0, stt = 0, sta = 0;
  for (std::size_t i = 0; i < t.size(); ++i) {
    st += t[i];
    sa += a[i];
    stt += t[i] * t[i];
    sta += t[i] * a[i];
  }
  const double den = n * stt - st * st;
  if (!(std::abs(den) > 1e-12)) return false;
  s = (n * sta - st * sa) / den;
  b = (sa - s * st) / n;
  return std::isfinite(s) && std::isfinite(b) && s != 0;
}
}  // namespace

CameraIntrinsics FitPinhole(const std::vector<PixelPoint>& points, int width, int height,
                            CameraIntrinsics fallback) {
  fallback.width = width;
  fallback.height = height;
  std::vector<double> u, v, ax, ay;
  for (const PixelPoint& p : points) {
    if (!(p.z > 0) || !std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
    u.push_back(p.u);
    v.push_back(p.v);
    ax.push_back(p.x / p.z);
    ay.push_back(p.y / p.z);
  }
  if (u.size() < 16) return fallback;
  double sx = 0, bx = 0, sy = 0, by = 0;
  if (!FitLine(u, ax, sx, bx) || !FitLine(v, ay, sy, by)) return fallback;
  CameraIntrinsics k = fallback;
  // x/z = (u - cx) / fx: slope 1/fx, intercept -cx/fx. A negative slope means the source's axis
  // points the other way; the focal length is its magnitude, cx is unaffected.
  k.fx_px = std::abs(1.0 / sx);
  k.cx_px = -bx / sx;
  k.fy_px = std::abs(1.0 / sy);
  k.cy_px = -by / sy;
  k.k1 = k.k2 = k.k3 = k.k4 = k.k5 = k.k6 = k.p1 = k.p2 = 0.0;
  try {
    k.Validate();
  } catch (const Error&) {
    return fallback;
  }
  return k;
}

}  // namespace tofcam::io_internal

#include "tofcam/sim/camera_model.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "yaml_util.h"

namespace tofcam::sim {
namespace {

using internal::YamlReader;

void Require(bool ok, const std::string& what) {
  if (!ok) throw Error(ErrorCode::kInvalidArgument, "camera model: " + what);
}

}  // namespace

void CameraModel::Validate() const {
  intrinsics.Validate();
  RequireUnfoldedDistortion(intrinsics);  // every simulated pixel casts rays
  Require(!name.empty(), "name must not be empty");
  Require(name.size() <= kMaxNameBytes, "name is " + std::to_string(name.size()) +
                                            " bytes, at most " + std::to_string(kMaxNameBytes));
  // The simulator keeps several float images and a ray table of supersampled rays per pixel; a
  // ToF sensor has at most about 1 Mpixel, and a recording holds frames of up to 2^22 pixels.
  Require(static_cast<long long>(intrinsics.width) * intrinsics.height <= kMaxPixels,
          "intrinsics " + std::to_string(intrinsics.width) + " x " +
              std::to_string(intrinsics.height) + " exceed " + std::to_string(kMaxPixels) +
              " pixels (2048 x 2048)");
  Require(!modulation_frequencies_hz.empty(), "modulation_frequencies_hz must not be empty");
  for (double f : modulation_frequencies_hz) {
    Require(std::isfinite(f) && f > 0, "modulation frequencies must be > 0 Hz");
  }
  Require(integration_time_step_us > 0, "integration_time_step_us must be > 0");
  Require(integration_time_base_us >= 0, "integration_time_base_us must be >= 0");
  Require(min_integration_register >= 0 && max_integration_register >= min_integration_register,
          "integration register range must satisfy 0 <= min <= max");
  Require(default_integration_register >= min_integration_register &&
              default_integration_register <= max_integration_register,
          "default_integration_register must lie in [min, max]");
  Require(max_frame_rate_hz > 0, "max_frame_rate_hz must be > 0");
  Require(readout_time_us >= 0, "readout_time_us must be >= 0");
  Require(led_power_w > 0, "led_power_w must be > 0");
  Require(led_half_angle_deg > 0 && led_half_angle_deg < 90,
          "led_half_angle_deg must be in (0, 90)");
  Require(wavelength_nm > 0, "wavelength_nm must be > 0");
  Require(f_number > 0, "f_number must be > 0");
  Require(pixel_pitch_x_um > 0 && pixel_pitch_y_um > 0, "pixel pitches must be > 0");
  Require(fill_factor > 0 && fill_factor <= 1, "fill_factor must be in (0, 1]");
  Require(quantum_efficiency > 0 && quantum_efficiency <= 1,
          "quantum_efficiency must be in (0, 1]");
  Require(tap_duty > 0 && tap_duty <= 1, "tap_duty must be in (0, 1]");
  Require(demodulation_contrast > 0 && demodulation_contrast <= 1,
          "demodulation_contrast must be in (0, 1]");
  Require(full_well_e > 0, "full_well_e must be > 0");
  Require(read_noise_e >= 0, "read_noise_e must be >= 0");
  Require(dark_current_e_per_s >= 0, "dark_current_e_per_s must be >= 0");
  Require(gain_reg_per_e > 0, "gain_reg_per_e must be > 0");
  Require(overflow_fraction >= 0 && overflow_fraction <= 1, "overflow_fraction must be in [0, 1]");
  Require(blooming_fraction >= 0 && blooming_fraction <= 1, "blooming_fraction must be in [0, 1]");
  Require(blooming_sigma_px > 0, "blooming_sigma_px must be > 0");
  double total = 0;
  for (const ScatterLobe& l : scattering) {
    Require(l.weight >= 0 && l.sigma_px > 0, "scattering lobes need weight >= 0 and sigma_px > 0");
    total += l.weight;
  }
  Require(total < 1.0, "scattering lobe weights must sum to < 1");
  Require(wiggle_amplitude_m >= 0 && fpn_bowl_m >= -1 && fpn_bowl_m <= 1 && fpn_spread_m >= 0 &&
              std::isfinite(wiggle_phase_rad),
          "wiggle_amplitude_m and fpn_spread_m must be >= 0, |fpn_bowl_m| <= 1");
  Require(std::abs(warmup_amplitude_m) <= 1 && warmup_time_constant_s > 0,
          "warmup_time_constant_s must be > 0 and |warmup_amplitude_m| <= 1");
  Require(std::isfinite(exposure_offset_m_per_ms), "exposure_offset_m_per_ms must be finite");
}

CameraInfo CameraModel::Info(double modulation_frequency_hz) const {
  CameraInfo info;
  info.model = name;
  info.intrinsics = intrinsics;
  info.modulation_frequency_hz = modulation_frequency_hz;
  info.integration_time_step_us = integration_time_step_us;
  info.integration_time_base_us = integration_time_base_us;
  info.min_integration_register = min_integration_register;
  info.max_integration_register = max_integration_register;
  info.max_frame_rate_hz = max_frame_rate_hz;
  info.readout_time_us = readout_time_us;
  info.has_intensity = true;
  info.has_ground_truth = true;
  return info;
}

CameraModel ParseCameraModel(std::string_view yaml_text, const std::string& source) {
  const YAML::Node root = internal::ParseYaml(std::string(yaml_text), source);
  const YamlReader r(source);
  if (!root.IsMap()) r.FailAt(0, "a camera model must be a YAML mapping");
  r.CheckKeys(root,
              {"name",
               "intrinsics",
               "modulation_frequencies_hz",
               "integration_time_step_us",
               "integration_time_base_us",
               "min_integration_register",
               "max_integration_register",
               "default_integration_register",
               "max_frame_rate_hz",
               "readout_time_us",
               "led_power_w",
               "led_half_angle_deg",
               "wavelength_nm",
               "f_number",
               "pixel_pitch_x_um",
               "pixel_pitch_y_um",
               "fill_factor",
               "quantum_efficiency",
               "tap_duty",
               "demodulation_contrast",
               "full_well_e",
               "read_noise_e",
               "dark_current_e_per_s",
               "gain_reg_per_e",
               "overflow_fraction",
               "blooming_fraction",
               "blooming_sigma_px",
               "scattering",
               "wiggle_amplitude_m",
               "wiggle_phase_rad",
               "fpn_bowl_m",
               "fpn_spread_m",
               "warmup_amplitude_m",
               "warmup_time_constant_s",
               "exposure_offset_m_per_ms",
               "unit_seed"},
              "camera model");
  CameraModel m;
  if (root["name"]) m.name = r.String(root["name"], "name");
  if (const YAML::Node k = root["intrinsics"]) {
    r.CheckKeys(k,
                {"width", "height", "fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "k3", "k4",
                 "k5", "k6", "p1", "p2"},
                "intrinsics");
    CameraIntrinsics& in = m.intrinsics;
    r.ReadInt(k, "width", in.width, 1, 16384);
    r.ReadInt(k, "height", in.height, 1, 16384);
    // Principal point defaults to the image centre of the (possibly new) size.
    in.cx_px = (in.width - 1) / 2.0;
    in.cy_px = (in.height - 1) / 2.0;
    r.Read(k, "fx_px", in.fx_px, 1e-3, 1e6);
    r.Read(k, "fy_px", in.fy_px, 1e-3, 1e6);
    r.Read(k, "cx_px", in.cx_px, -1e6, 1e6);
    r.Read(k, "cy_px", in.cy_px, -1e6, 1e6);
    for (auto [key, ptr] : {std::pair{"k1", &in.k1},
                            {"k2", &in.k2},
                            {"k3", &in.k3},
                            {"k4", &in.k4},
                            {"k5", &in.k5},
                            {"k6", &in.k6},
                            {"p1", &in.p1},
                            {"p2", &in.p2}}) {
      r.Read(k, key, *ptr, -1e3, 1e3);
    }
  }
  if (const YAML::Node f = root["modulation_frequencies_hz"]) {
    if (!f.IsSequence() || f.size() == 0) r.Fail(f, "modulation_frequencies_hz must be a list");
    m.modulation_frequencies_hz.clear();
    for (const auto& e : f)
      m.modulation_frequencies_hz.push_back(r.Number(e, "frequency", 1e3, 1e10));
  }
  r.Read(root, "integration_time_step_us", m.integration_time_step_us, 1e-3, 1e6);
  r.Read(root, "integration_time_base_us", m.integration_time_base_us, 0, 1e6);
  r.ReadInt(root, "min_integration_register", m.min_integration_register, 0, 1 << 20);
  r.ReadInt(root, "max_integration_register", m.max_integration_register, 0, 1 << 20);
  r.ReadInt(root, "default_integration_register", m.default_integration_register, 0, 1 << 20);
  r.Read(root, "max_frame_rate_hz", m.max_frame_rate_hz, 1e-3, 1e4);
  r.Read(root, "readout_time_us", m.readout_time_us, 0, 1e7);
  r.Read(root, "led_power_w", m.led_power_w, 1e-9, 1e4);
  r.Read(root, "led_half_angle_deg", m.led_half_angle_deg, 1e-3, 89.9);
  r.Read(root, "wavelength_nm", m.wavelength_nm, 100, 100000);
  r.Read(root, "f_number", m.f_number, 0.1, 100);
  r.Read(root, "pixel_pitch_x_um", m.pixel_pitch_x_um, 0.01, 1000);
  r.Read(root, "pixel_pitch_y_um", m.pixel_pitch_y_um, 0.01, 1000);
  r.Read(root, "fill_factor", m.fill_factor, 1e-6, 1);
  r.Read(root, "quantum_efficiency", m.quantum_efficiency, 1e-6, 1);
  r.Read(root, "tap_duty", m.tap_duty, 1e-6, 1);
  r.Read(root, "demodulation_contrast", m.demodulation_contrast, 1e-6, 1);
  r.Read(root, "full_well_e", m.full_well_e, 1, 1e9);
  r.Read(root, "read_noise_e", m.read_noise_e, 0, 1e6);
  r.Read(root, "dark_current_e_per_s", m.dark_current_e_per_s, 0, 1e12);
  r.Read(root, "gain_reg_per_e", m.gain_reg_per_e, 1e-9, 1e6);
  r.Read(root, "overflow_fraction", m.overflow_fraction, 0, 1);
  r.Read(root, "blooming_fraction", m.blooming_fraction, 0, 1);
  r.Read(root, "blooming_sigma_px", m.blooming_sigma_px, 1e-3, 1000);
  if (const YAML::Node s = root["scattering"]) {
    if (!s.IsSequence()) r.Fail(s, "scattering must be a list of {weight, sigma_px}");
    m.scattering.clear();
    for (const auto& lobe : s) {
      r.CheckKeys(lobe, {"weight", "sigma_px"}, "scattering lobe");
      ScatterLobe l;
      r.Read(lobe, "weight", l.weight, 0, 0.99);
      l.sigma_px = 1.0;
      r.Read(lobe, "sigma_px", l.sigma_px, 0.1, 10000);
      m.scattering.push_back(l);
    }
  }
  r.Read(root, "wiggle_amplitude_m", m.wiggle_amplitude_m, 0, 1);
  r.Read(root, "wiggle_phase_rad", m.wiggle_phase_rad, -100, 100);
  r.Read(root, "fpn_bowl_m", m.fpn_bowl_m, -1, 1);
  r.Read(root, "fpn_spread_m", m.fpn_spread_m, 0, 1);
  r.Read(root, "warmup_amplitude_m", m.warmup_amplitude_m, -1, 1);
  r.Read(root, "warmup_time_constant_s", m.warmup_time_constant_s, 1e-3, 1e7);
  r.Read(root, "exposure_offset_m_per_ms", m.exposure_offset_m_per_ms, -1, 1);
  if (const YAML::Node s = root["unit_seed"]) {
    m.unit_seed = static_cast<std::uint64_t>(r.Number(s, "unit_seed", 0, 1e15));
  }
  try {
    m.Validate();
  } catch (const Error& e) {
    throw Error(ErrorCode::kFormat, source + ": " + e.what());
  }
  return m;
}

CameraModel LoadCameraModel(const std::filesystem::path& path) {
  return ParseCameraModel(ReadFile(path, 1 << 20), path.string());
}

std::vector<std::string> BuiltinCameraModelNames() {
  std::vector<std::string> names;
  for (int i = 0; i < internal::kEmbeddedFileCount; ++i) {
    const std::string p = internal::kEmbeddedFiles[i].path;
    if (p.rfind("cameras/", 0) == 0 && p.size() > 13) {
      names.push_back(p.substr(8, p.size() - 8 - 5));
    }
  }
  return names;
}

CameraModel ResolveCameraModel(const std::string& name_or_path) {
  const std::string name = name_or_path.empty() ? "sr2" : name_or_path;
  for (int i = 0; i < internal::kEmbeddedFileCount; ++i) {
    if (internal::kEmbeddedFiles[i].path == "cameras/" + name + ".yaml") {
      return ParseCameraModel(internal::kEmbeddedFiles[i].content,
                              "<builtin>/cameras/" + name + ".yaml");
    }
  }
  const std::filesystem::path p(name);
  if (p.extension() == ".yaml" || p.extension() == ".yml" || std::filesystem::exists(p)) {
    return LoadCameraModel(p);
  }
  std::string known;
  for (const auto& n : BuiltinCameraModelNames()) known += (known.empty() ? "" : ", ") + n;
  throw Error(ErrorCode::kNotFound,
              "unknown camera model '" + name + "' (built-in: " + known + "; or a .yaml file)");
}

CameraModel WithResolution(CameraModel model, int width, int height) {
  if (width < 1 || width > 16384 || height < 1 || height > 16384) {
    throw Error(ErrorCode::kInvalidArgument, "camera resolution " + std::to_string(width) + " x " +
                                                 std::to_string(height) +
                                                 " outside 1..16384 per side");
  }
  CameraIntrinsics& k = model.intrinsics;
  k.fx_px *= width / static_cast<double>(k.width);
  k.fy_px *= height / static_cast<double>(k.height);
  k.width = width;
  k.height = height;
  k.cx_px = (width - 1) / 2.0;
  k.cy_px = (height - 1) / 2.0;
  return model;
}

}  // namespace tofcam::sim

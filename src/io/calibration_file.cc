#include "tofcam/io/calibration_file.h"

#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <set>
#include <string>

#include "../core/yaml_checks.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

// The model's numbers in file order (names = the YAML keys).
std::vector<std::pair<std::string, double>> NoiseModelFields(const NoiseModel& m) {
  return {{"intercept", m.intercept},
          {"log_amplitude", m.log_amplitude},
          {"log_intensity", m.log_intensity},
          {"log_distance", m.log_distance},
          {"amplitude_fraction", m.amplitude_fraction},
          {"amplitude_ref", m.amplitude_ref},
          {"log_confidence", m.log_confidence},
          {"log_edge", m.log_edge},
          {"edge_ref_m", m.edge_ref_m}};
}

constexpr const char* kFormatTag = "tofcam-calibration";
constexpr int kMaxSide = 16384;
constexpr long long kMaxPixels = 1LL << 24;
constexpr std::size_t kMaxFileBytes = std::size_t{256} << 20;

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

class Reader {
 public:
  explicit Reader(std::string source) : source_(std::move(source)) {}

  [[noreturn]] void Fail(const YAML::Node& node, const std::string& problem) const {
    std::string where = source_;
    const YAML::Mark mark = node.Mark();
    if (mark.line >= 0) where += ":" + std::to_string(mark.line + 1);
    throw Error(ErrorCode::kFormat, where + ": " + problem);
  }
  [[noreturn]] void Fail(const std::string& problem) const {
    throw Error(ErrorCode::kFormat, source_ + ": " + problem);
  }

  YAML::Node Required(const YAML::Node& map, const std::string& key) const {
    const YAML::Node node = map[key];
    if (!node) Fail(map, "missing key '" + key + "'");
    return node;
  }

  double Double(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) Fail(node, what + " must be a number");
    const std::string& s = node.Scalar();
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(s.c_str(), &end);
    if (s.empty() || end != s.c_str() + s.size() || errno == ERANGE) {
      Fail(node, what + " = '" + s + "' is not a number");
    }
    if (!std::isfinite(v)) Fail(node, what + " = '" + s + "' is not finite");
    return v;
  }

  long long Integer(const YAML::Node& node, const std::string& what, long long lo,
                    long long hi) const {
    if (!node.IsScalar()) Fail(node, what + " must be an integer");
    const std::string& s = node.Scalar();
    char* end = nullptr;
    errno = 0;
    const long long v = std::strtoll(s.c_str(), &end, 10);
    if (s.empty() || end != s.c_str() + s.size() || errno == ERANGE) {
      Fail(node, what + " = '" + s + "' is not an integer");
    }
    if (v < lo || v > hi) {
      Fail(node, what + " = " + s + " is outside [" + std::to_string(lo) + ", " +
                     std::to_string(hi) + "]");
    }
    return v;
  }

  std::string String(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) Fail(node, what + " must be a string");
    return node.Scalar();
  }

  void CheckKeys(const YAML::Node& map, const std::set<std::string>& allowed,
                 const std::string& what) const {
    if (!map.IsMap()) Fail(map, what + " must be a mapping");
    for (const auto& kv : map) {
      if (!kv.first.IsScalar()) Fail(kv.first, "non-scalar key in " + what);
      const std::string key = kv.first.Scalar();
      if (!allowed.count(key)) Fail(kv.first, "unknown key '" + key + "' in " + what);
    }
  }

  YAML::Node Sequence(const YAML::Node& node, const std::string& what, std::size_t size) const {
    if (!node.IsSequence()) Fail(node, what + " must be a sequence");
    if (size != 0 && node.size() != size) {
      Fail(node, what + " has " + std::to_string(node.size()) + " entries, expected " +
                     std::to_string(size));
    }
    return node;
  }

 private:
  std::string source_;
};

}  // namespace

void SaveCalibration(const std::filesystem::path& path, const OffsetCalibration& calibration) {
  calibration.Validate();
  YAML::Emitter out;
  out.SetFloatPrecision(9);    // float round trip
  out.SetDoublePrecision(17);  // double round trip
  out << YAML::Comment("tofcam per-pixel distance calibration; format: docs/calibration.md");
  out << YAML::BeginMap;
  out << YAML::Key << "format" << YAML::Value << kFormatTag;
  out << YAML::Key << "version" << YAML::Value << calibration.version;
  out << YAML::Key << "camera_model" << YAML::Value << YAML::DoubleQuoted
      << calibration.camera_model;
  out << YAML::Key << "width" << YAML::Value << calibration.width;
  out << YAML::Key << "height" << YAML::Value << calibration.height;
  out << YAML::Key << "modulation_frequency_hz" << YAML::Value
      << calibration.modulation_frequency_hz;
  out << YAML::Key << "integration_time_us" << YAML::Value << calibration.integration_time_us;
  out << YAML::Key << "integration_time_register" << YAML::Value
      << calibration.integration_time_register;
  out << YAML::Key << "created_unix_s" << YAML::Value << calibration.created_unix_s;
  out << YAML::Key << "wall_distance_m" << YAML::Value << calibration.wall_distance_m;
  out << YAML::Key << "wall_normal" << YAML::Value << YAML::Flow << YAML::BeginSeq
      << calibration.wall_normal[0] << calibration.wall_normal[1] << calibration.wall_normal[2]
      << YAML::EndSeq;
  out << YAML::Key << "frames_averaged" << YAML::Value << calibration.frames_averaged;
  out << YAML::Key << "exposure_offset_m_per_ms" << YAML::Value
      << calibration.exposure_offset_m_per_ms;
  out << YAML::Key << "offset_m" << YAML::Value << YAML::BeginSeq;
  for (int r = 0; r < calibration.height; ++r) {
    out << YAML::Flow << YAML::BeginSeq;
    for (float v : calibration.offset_m.Row(r)) out << v;
    out << YAML::EndSeq;
  }
  out << YAML::EndSeq;
  out << YAML::Key << "uncalibrated_pixels" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  if (!calibration.pixel_flags.empty()) {
    for (int r = 0; r < calibration.height; ++r) {
      for (int c = 0; c < calibration.width; ++c) {
        if (calibration.pixel_flags(r, c).Has(Flag::kInvalid)) {
          out << YAML::Flow << YAML::BeginSeq << r << c << YAML::EndSeq;
        }
      }
    }
  }
  out << YAML::EndSeq;
  if (calibration.distance_correction) {
    const DistanceCorrection& g = *calibration.distance_correction;
    out << YAML::Key << "distance_correction" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "start_m" << YAML::Value << g.start_m;
    out << YAML::Key << "step_m" << YAML::Value << g.step_m;
    out << YAML::Key << "correction_m" << YAML::Value << YAML::Flow << YAML::BeginSeq;
    for (float v : g.correction_m) out << v;
    out << YAML::EndSeq << YAML::EndMap;
  }
  if (calibration.noise) {
    const NoiseCalibration& n = *calibration.noise;
    out << YAML::Key << "noise" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "delta_l_scale" << YAML::Value << n.delta_l_scale;
    out << YAML::Key << "r_squared" << YAML::Value << n.r_squared;
    out << YAML::Key << "frames" << YAML::Value << n.frames;
    out << YAML::Key << "pixels_used" << YAML::Value << n.pixels_used;
    if (n.model) {
      const NoiseModel& m = *n.model;
      out << YAML::Key << "model" << YAML::Value << YAML::BeginMap;
      for (const auto& [key, value] : NoiseModelFields(m)) {
        out << YAML::Key << key << YAML::Value << value;
      }
      out << YAML::Key << "held_out_spearman" << YAML::Value << n.model_spearman;
      out << YAML::Key << "eq2_held_out_spearman" << YAML::Value << n.eq2_spearman;
      out << YAML::Key << "held_out_max_decile_error" << YAML::Value << n.model_max_decile_error;
      out << YAML::EndMap;
    }
    out << YAML::EndMap;
  }
  if (calibration.controller_setpoint) {
    const ControllerSetpoint& p = *calibration.controller_setpoint;
    out << YAML::Key << "controller_setpoint" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "target_intensity" << YAML::Value << p.target_intensity;
    out << YAML::Key << "bias_register" << YAML::Value << p.bias_register;
    out << YAML::Key << "gain_register_per_intensity" << YAML::Value
        << p.gain_register_per_intensity;
    out << YAML::Key << "amplitude_max_register" << YAML::Value << p.amplitude_max_register;
    out << YAML::Key << "amplitude_max_intensity" << YAML::Value << p.amplitude_max_intensity;
    out << YAML::Key << "intensity_per_register" << YAML::Value << p.intensity_per_register;
    out << YAML::Key << "scene" << YAML::Value << YAML::DoubleQuoted << p.scene;
    out << YAML::EndMap;
  }
  if (calibration.scattering) {
    const ScatteringCalibration& sc = *calibration.scattering;
    out << YAML::Key << "scattering" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "lobes" << YAML::Value << YAML::BeginSeq;
    for (const ScatteringLobe& l : sc.lobes) {
      out << YAML::Flow << YAML::BeginMap << YAML::Key << "weight" << YAML::Value << l.weight
          << YAML::Key << "sigma_px" << YAML::Value << l.sigma_px << YAML::EndMap;
    }
    out << YAML::EndSeq;
    out << YAML::Key << "frames" << YAML::Value << sc.frames;
    out << YAML::Key << "integration_time_register" << YAML::Value << sc.integration_time_register;
    out << YAML::Key << "target_pixels" << YAML::Value << sc.target_pixels;
    out << YAML::Key << "fit_pixels" << YAML::Value << sc.fit_pixels;
    out << YAML::Key << "explained_fraction" << YAML::Value << sc.explained_fraction;
    out << YAML::EndMap;
  }
  out << YAML::EndMap;
  if (!out.good()) {
    throw Error(ErrorCode::kInternal, "calibration YAML emitter: " + out.GetLastError());
  }
  WriteFileAtomically(path, std::string(out.c_str()) + "\n");
}

OffsetCalibration LoadCalibration(const std::filesystem::path& path) {
  const std::string source = path.string();
  const std::string text = ReadFile(path, kMaxFileBytes);
  const Reader in(source);
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw Error(ErrorCode::kFormat,
                source + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg);
  }
  internal::RejectDuplicateKeys(root, source);
  if (!root.IsMap()) in.Fail("not a tofcam calibration file (expected a YAML mapping)");
  const YAML::Node format = in.Required(root, "format");
  if (in.String(format, "format") != kFormatTag) {
    in.Fail(format, "format is '" + format.Scalar() + "', expected '" + kFormatTag + "'");
  }
  OffsetCalibration c;
  const YAML::Node version = in.Required(root, "version");
  const int file_version = static_cast<int>(in.Integer(version, "version", 0, 1 << 30));
  if (file_version < 1 || file_version > OffsetCalibration::kVersion) {
    in.Fail(version, "unsupported version " + std::to_string(file_version) +
                         " (this build reads versions 1 to " +
                         std::to_string(OffsetCalibration::kVersion) + ")");
  }
  // Version 1 predates the exposure offset, the noise calibration and the controller set point:
  // it loads with s = 0 (no exposure compensation, as it was applied then) and neither section.
  std::set<std::string> keys = {"format",
                                "version",
                                "camera_model",
                                "width",
                                "height",
                                "modulation_frequency_hz",
                                "integration_time_us",
                                "integration_time_register",
                                "created_unix_s",
                                "wall_distance_m",
                                "wall_normal",
                                "frames_averaged",
                                "offset_m",
                                "uncalibrated_pixels",
                                "distance_correction"};
  if (file_version >= 2) keys.insert({"exposure_offset_m_per_ms", "noise", "controller_setpoint"});
  if (file_version >= 3) keys.insert("scattering");
  in.CheckKeys(root, keys, "calibration version " + std::to_string(file_version));
  c.version = OffsetCalibration::kVersion;
  c.camera_model = in.String(in.Required(root, "camera_model"), "camera_model");
  c.width = static_cast<int>(in.Integer(in.Required(root, "width"), "width", 1, kMaxSide));
  c.height = static_cast<int>(in.Integer(in.Required(root, "height"), "height", 1, kMaxSide));
  if (static_cast<long long>(c.width) * c.height > kMaxPixels) {
    in.Fail(root["height"], "size " + std::to_string(c.width) + "x" + std::to_string(c.height) +
                                " exceeds 2^24 pixels");
  }
  const YAML::Node freq = in.Required(root, "modulation_frequency_hz");
  c.modulation_frequency_hz = in.Double(freq, "modulation_frequency_hz");
  if (c.modulation_frequency_hz <= 0.0) in.Fail(freq, "modulation_frequency_hz must be > 0");
  c.integration_time_us =
      in.Double(in.Required(root, "integration_time_us"), "integration_time_us");
  c.integration_time_register = static_cast<int>(in.Integer(
      in.Required(root, "integration_time_register"), "integration_time_register", 0, 65535));
  c.created_unix_s = in.Integer(in.Required(root, "created_unix_s"), "created_unix_s", 0,
                                std::numeric_limits<long long>::max());
  c.wall_distance_m = in.Double(in.Required(root, "wall_distance_m"), "wall_distance_m");
  const YAML::Node normal = in.Sequence(in.Required(root, "wall_normal"), "wall_normal", 3);
  for (int k = 0; k < 3; ++k) c.wall_normal[k] = in.Double(normal[k], "wall_normal");
  c.frames_averaged = static_cast<int>(
      in.Integer(in.Required(root, "frames_averaged"), "frames_averaged", 0, 1 << 30));
  if (file_version >= 2) {
    const YAML::Node slope = in.Required(root, "exposure_offset_m_per_ms");
    c.exposure_offset_m_per_ms = in.Double(slope, "exposure_offset_m_per_ms");
    if (std::abs(c.exposure_offset_m_per_ms) > 0.1) {
      in.Fail(slope, "exposure_offset_m_per_ms = " + Num(c.exposure_offset_m_per_ms) +
                         " is beyond ±0.1 m/ms");
    }
  }
  if (const YAML::Node noise = root["noise"]) {
    in.CheckKeys(noise, {"delta_l_scale", "r_squared", "frames", "pixels_used", "model"}, "noise");
    NoiseCalibration n;
    const YAML::Node scale = in.Required(noise, "delta_l_scale");
    n.delta_l_scale = in.Double(scale, "noise.delta_l_scale");
    if (!(n.delta_l_scale > 0.0 && n.delta_l_scale <= 1e6)) {
      in.Fail(scale, "noise.delta_l_scale = " + Num(n.delta_l_scale) + " must be in (0, 1e6]");
    }
    n.r_squared = in.Double(in.Required(noise, "r_squared"), "noise.r_squared");
    n.frames =
        static_cast<int>(in.Integer(in.Required(noise, "frames"), "noise.frames", 0, 1 << 30));
    n.pixels_used = static_cast<int>(
        in.Integer(in.Required(noise, "pixels_used"), "noise.pixels_used", 0, 1 << 30));
    if (const YAML::Node model = noise["model"]) {
      NoiseModel m;
      std::set<std::string> model_keys{"held_out_spearman", "eq2_held_out_spearman",
                                       "held_out_max_decile_error"};
      for (const auto& [key, value] : NoiseModelFields(m)) model_keys.insert(key);
      in.CheckKeys(model, model_keys, "noise.model");
      m.intercept = in.Double(in.Required(model, "intercept"), "noise.model.intercept");
      m.log_amplitude = in.Double(in.Required(model, "log_amplitude"), "noise.model.log_amplitude");
      m.log_intensity = in.Double(in.Required(model, "log_intensity"), "noise.model.log_intensity");
      m.log_distance = in.Double(in.Required(model, "log_distance"), "noise.model.log_distance");
      m.amplitude_fraction =
          in.Double(in.Required(model, "amplitude_fraction"), "noise.model.amplitude_fraction");
      m.amplitude_ref = in.Double(in.Required(model, "amplitude_ref"), "noise.model.amplitude_ref");
      m.log_confidence =
          in.Double(in.Required(model, "log_confidence"), "noise.model.log_confidence");
      // The edge channel came later: files without it have none.
      if (model["log_edge"]) m.log_edge = in.Double(model["log_edge"], "noise.model.log_edge");
      if (model["edge_ref_m"]) {
        m.edge_ref_m = in.Double(model["edge_ref_m"], "noise.model.edge_ref_m");
      }
      try {
        m.Validate();
      } catch (const Error& e) {
        in.Fail(model, e.what());
      }
      n.model = m;
      n.model_spearman =
          in.Double(in.Required(model, "held_out_spearman"), "noise.model.held_out_spearman");
      n.eq2_spearman = in.Double(in.Required(model, "eq2_held_out_spearman"),
                                 "noise.model.eq2_held_out_spearman");
      n.model_max_decile_error = in.Double(in.Required(model, "held_out_max_decile_error"),
                                           "noise.model.held_out_max_decile_error");
    }
    try {
      n.Validate();
    } catch (const Error& e) {
      in.Fail(noise, e.what());
    }
    c.noise = n;
  }
  if (const YAML::Node sp = root["controller_setpoint"]) {
    in.CheckKeys(
        sp,
        {"target_intensity", "bias_register", "gain_register_per_intensity",
         "amplitude_max_register", "amplitude_max_intensity", "intensity_per_register", "scene"},
        "controller_setpoint");
    ControllerSetpoint p;
    const YAML::Node target = in.Required(sp, "target_intensity");
    p.target_intensity = in.Double(target, "controller_setpoint.target_intensity");
    if (!(p.target_intensity > 0.0 && p.target_intensity <= 65532.0)) {
      in.Fail(target, "controller_setpoint.target_intensity = " + Num(p.target_intensity) +
                          " must be in (0, 65532]");
    }
    p.bias_register = static_cast<int>(in.Integer(in.Required(sp, "bias_register"),
                                                  "controller_setpoint.bias_register", 1, 65535));
    const YAML::Node gain = in.Required(sp, "gain_register_per_intensity");
    p.gain_register_per_intensity =
        in.Double(gain, "controller_setpoint.gain_register_per_intensity");
    if (!(p.gain_register_per_intensity >= 0.0 && p.gain_register_per_intensity <= 1.0)) {
      in.Fail(gain, "controller_setpoint.gain_register_per_intensity = " +
                        Num(p.gain_register_per_intensity) + " must be in [0, 1]");
    }
    p.amplitude_max_register =
        static_cast<int>(in.Integer(in.Required(sp, "amplitude_max_register"),
                                    "controller_setpoint.amplitude_max_register", 0, 65535));
    p.amplitude_max_intensity = in.Double(in.Required(sp, "amplitude_max_intensity"),
                                          "controller_setpoint.amplitude_max_intensity");
    p.intensity_per_register = in.Double(in.Required(sp, "intensity_per_register"),
                                         "controller_setpoint.intensity_per_register");
    p.scene = in.String(in.Required(sp, "scene"), "controller_setpoint.scene");
    c.controller_setpoint = std::move(p);
  }

  if (const YAML::Node sc = root["scattering"]) {
    in.CheckKeys(sc,
                 {"lobes", "frames", "integration_time_register", "target_pixels", "fit_pixels",
                  "explained_fraction"},
                 "scattering");
    ScatteringCalibration k;
    const YAML::Node lobes = in.Sequence(in.Required(sc, "lobes"), "scattering.lobes", 0);
    if (lobes.size() < 1 || lobes.size() > 2) {
      in.Fail(lobes,
              "scattering.lobes has " + std::to_string(lobes.size()) + " entries, expected 1 or 2");
    }
    for (const YAML::Node& lobe : lobes) {
      in.CheckKeys(lobe, {"weight", "sigma_px"}, "scattering.lobes entry");
      ScatteringLobe l;
      l.weight = in.Double(in.Required(lobe, "weight"), "scattering.lobes.weight");
      l.sigma_px = in.Double(in.Required(lobe, "sigma_px"), "scattering.lobes.sigma_px");
      k.lobes.push_back(l);
    }
    k.frames =
        static_cast<int>(in.Integer(in.Required(sc, "frames"), "scattering.frames", 1, 1 << 30));
    k.integration_time_register =
        static_cast<int>(in.Integer(in.Required(sc, "integration_time_register"),
                                    "scattering.integration_time_register", 0, 65535));
    k.target_pixels = static_cast<int>(
        in.Integer(in.Required(sc, "target_pixels"), "scattering.target_pixels", 0, 1 << 30));
    k.fit_pixels = static_cast<int>(
        in.Integer(in.Required(sc, "fit_pixels"), "scattering.fit_pixels", 0, 1 << 30));
    k.explained_fraction =
        in.Double(in.Required(sc, "explained_fraction"), "scattering.explained_fraction");
    try {
      k.Validate();
    } catch (const Error& e) {
      in.Fail(sc, e.what());
    }
    c.scattering = std::move(k);
  }

  const YAML::Node rows =
      in.Sequence(in.Required(root, "offset_m"), "offset_m", static_cast<std::size_t>(c.height));
  c.offset_m = Image<float>(c.width, c.height);
  const double half_range = UnambiguousRangeM(c.modulation_frequency_hz) / 2.0;
  for (int r = 0; r < c.height; ++r) {
    const std::string what = "offset_m row " + std::to_string(r);
    const YAML::Node row = in.Sequence(rows[r], what, static_cast<std::size_t>(c.width));
    for (int col = 0; col < c.width; ++col) {
      const YAML::Node v = row[col];
      const double o = in.Double(v, what + ", col " + std::to_string(col));
      if (std::abs(o) > half_range) {
        in.Fail(v, what + ", col " + std::to_string(col) + ": offset " + Num(o) +
                       " m beyond ±L/2 = " + Num(half_range) + " m");
      }
      c.offset_m(r, col) = static_cast<float>(o);
    }
  }
  const YAML::Node bad =
      in.Sequence(in.Required(root, "uncalibrated_pixels"), "uncalibrated_pixels", 0);
  if (bad.size() > 0) {
    c.pixel_flags = Image<PixelFlags>(c.width, c.height);
    for (const YAML::Node& p : bad) {
      in.Sequence(p, "uncalibrated_pixels entry", 2);
      const auto r = static_cast<int>(in.Integer(p[0], "uncalibrated pixel row", 0, c.height - 1));
      const auto col = static_cast<int>(in.Integer(p[1], "uncalibrated pixel col", 0, c.width - 1));
      c.pixel_flags(r, col) = PixelFlags(Flag::kInvalid);
    }
  }
  if (const YAML::Node dc = root["distance_correction"]) {
    in.CheckKeys(dc, {"start_m", "step_m", "correction_m"}, "distance_correction");
    DistanceCorrection g;
    g.start_m = in.Double(in.Required(dc, "start_m"), "distance_correction.start_m");
    g.step_m = in.Double(in.Required(dc, "step_m"), "distance_correction.step_m");
    const YAML::Node values =
        in.Sequence(in.Required(dc, "correction_m"), "distance_correction.correction_m", 0);
    if (values.size() > (1u << 20)) in.Fail(values, "distance_correction has over 2^20 knots");
    for (const YAML::Node& v : values) {
      g.correction_m.push_back(static_cast<float>(in.Double(v, "distance_correction value")));
    }
    c.distance_correction = std::move(g);
  }
  try {
    c.Validate();
  } catch (const Error& e) {
    in.Fail(e.what());
  }
  return c;
}

void CheckCalibrationMatches(const OffsetCalibration& calibration, const CameraInfo& camera) {
  const auto mismatch = [](const std::string& field, const std::string& file_value,
                           const std::string& camera_value) {
    throw Error(ErrorCode::kMismatch, "calibration does not fit the camera: " + field + " is " +
                                          file_value + " in the calibration, " + camera_value +
                                          " on the camera");
  };
  if (calibration.camera_model != camera.model) {
    mismatch("camera model", "'" + calibration.camera_model + "'", "'" + camera.model + "'");
  }
  if (calibration.width != camera.width()) {
    mismatch("width", std::to_string(calibration.width), std::to_string(camera.width()));
  }
  if (calibration.height != camera.height()) {
    mismatch("height", std::to_string(calibration.height), std::to_string(camera.height()));
  }
  if (!(std::abs(calibration.modulation_frequency_hz - camera.modulation_frequency_hz) <=
        1e-9 * camera.modulation_frequency_hz)) {
    mismatch("modulation frequency", Num(calibration.modulation_frequency_hz) + " Hz",
             Num(camera.modulation_frequency_hz) + " Hz");
  }
}

}  // namespace tofcam

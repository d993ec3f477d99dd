#include "tofcam/io/pipeline_config.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "../core/yaml_checks.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/io/calibration_file.h"

namespace tofcam {
namespace {

// A flag mask in the file is a list of flag names (FlagName), e.g. [invalid, saturated].
struct FlagMask {
  std::uint16_t& bits;
};

// A camera-specific value that ApplyMeasuredDefaults fills from measurements when the file does
// not give it. The writer prints it commented out while it holds the default, so a printed
// configuration read back does not pin the default over the camera's measured value.
template <typename T>
struct Measured {
  T& value;
  T default_value;
};

// One description of the file's layout, walked by both the writer and the reader, so the two
// cannot disagree about a key, its section or its type.
template <typename V>
void VisitOptions(V& v, PipelineOptions& o) {
  const PipelineOptions defaults;
  v.Section("metric_conversion", "Stage 1: registers to metres", [&] {
    v.Field("remove_distance_offset_register", o.metric.remove_distance_offset_register,
            "subtract the camera's distance-offset register before scaling");
  });
  v.Section("calibration", "Stage 2: per-pixel offsets, eq. 1 (tofcam calibrate writes them)", [&] {
    v.Field("file", o.calibration_file, "calibration file, \"\" = none; relative to this file");
    v.Field("alternate_file", o.alternate_calibration_file,
            "calibration made at frame_pair's alternate frequency, \"\" = none");
  });
  v.Section("scattering", "compensation of in-camera scattering, before stage 1 (not in the paper)",
            [&] {
              // Two lobes in the file; a lobe of weight 0 does nothing.
              if (o.scattering.lobes.size() < 2) o.scattering.lobes.resize(2, {0.0, 8.0});
              v.Field("enabled", o.scattering_enabled, "");
              v.Field("iterations", o.scattering.iterations, "fixed-point iterations, [1, 20]");
              v.Field("weight_1", o.scattering.lobes[0].weight, "fraction of light, [0, 0.5)");
              v.Field("sigma_1_px", o.scattering.lobes[0].sigma_px, "pixels, (0, 1000]");
              v.Field("weight_2", o.scattering.lobes[1].weight, "fraction of light, [0, 0.5)");
              v.Field("sigma_2_px", o.scattering.lobes[1].sigma_px, "pixels, (0, 1000]");
            });
  v.Section("accuracy", "Stage 3: predicted inaccuracy ΔL, eq. 2", [&] {
    v.Field("enabled", o.accuracy_enabled, "compute ΔL (the accuracy filter needs it)");
    v.Field("scale", Measured<double>{o.accuracy.scale, defaults.accuracy.scale},
            "factor on eq. 2, (0, 1e6]; 1 = the paper's formula; left out: measured per camera");
    v.Field("intensity_per_amplitude", o.accuracy.intensity_per_amplitude,
            "I/A for sources without intensity, (0, 1e6]");
  });
  v.Section("filters", "Stage 5: each filter raises its own flag", [&] {
    v.Section("range", "radial distance limits", [&] {
      v.Field("enabled", o.filters.range_enabled, "");
      v.Field("min_distance_m", o.filters.range.min_distance_m, "m, >= 0");
      v.Field("max_distance_m", o.filters.range.max_distance_m, "m, > min_distance_m");
    });
    v.Section("amplitude", "the vendor driver's amplitude threshold", [&] {
      v.Field("enabled", o.filters.amplitude_enabled, "");
      v.Field("min_amplitude", o.filters.amplitude.min_amplitude, "register units, [0, 65532]");
    });
    v.Section("saturation", "saturation from the registers", [&] {
      v.Field("enabled", o.filters.saturation_enabled, "");
      v.Field("max_intensity", o.filters.saturation.max_intensity, "register units, > 0");
      v.Field("max_amplitude", o.filters.saturation.max_amplitude, "register units, > 0");
      v.Field("max_peak", o.filters.saturation.max_peak,
              "intensity + amplitude, register units, > 0");
    });
    v.Section("accuracy", "the paper's ΔL threshold (section III-B)", [&] {
      v.Field("enabled", o.filters.accuracy_enabled, "");
      v.Field("max_delta_l_m", o.filters.accuracy.max_delta_l_m, "m, (0, 100]");
    });
    v.Section("confidence", "the camera's own confidence channel, where it has one", [&] {
      v.Field("enabled", o.filters.confidence_enabled, "");
      v.Field("min_confidence", o.filters.confidence.min_confidence,
              "camera units (higher = better), [0, 1e9]");
    });
    v.Section("flying_pixel", "edge-aware flying-pixel filter (libfreenect2 style)", [&] {
      v.Field("enabled", o.filters.flying_pixel_enabled, "");
      v.Field("min_amplitude_contrast", o.filters.flying_pixel.min_amplitude_contrast, ">= 0");
      v.Field("amplitude_mean_floor", o.filters.flying_pixel.amplitude_mean_floor,
              "register units, > 0");
      v.Field("min_close_delta_m", o.filters.flying_pixel.min_close_delta_m, "m, >= 0");
      v.Field("min_far_delta_m", o.filters.flying_pixel.min_far_delta_m, "m, >= 0");
      v.Field("min_max_delta_m", o.filters.flying_pixel.min_max_delta_m, "m, >= 0");
      v.Field("min_avg_delta_m", o.filters.flying_pixel.min_avg_delta_m, "m, >= 0");
    });
    v.Section("jump_edge", "jump-edge filter (May et al.)", [&] {
      v.Field("enabled", o.filters.jump_edge_enabled, "");
      v.Field("max_angle_deg", o.filters.jump_edge.max_angle_deg, "degrees, (90, 180)");
    });
    v.Section("weingarten", "occupied cells (Weingarten et al.)", [&] {
      v.Field("enabled", o.filters.weingarten_enabled, "");
      v.Field("voxel_size_m", o.filters.weingarten.voxel_size_m, "m, [0.001, 100]");
      v.Field("min_points", o.filters.weingarten.min_points, "[1, 1000000]");
    });
  });
  v.Section("uncertainty", "ΔL plus edges in metres, one threshold (not in the paper)", [&] {
    v.Field("enabled", o.uncertainty_enabled, "needs accuracy.enabled");
    v.Field("max_uncertainty_m", o.uncertainty.max_uncertainty_m, "m, (0, 100]");
    v.Field("edge_fraction", o.uncertainty.edge_fraction, "part of an edge's jump, [0, 1]");
    v.Field("min_jump_sigma", o.uncertainty.min_jump_sigma, "steps below are noise, (0, 100]");
    v.Field("extrapolate_edges", o.uncertainty.extrapolate_edges,
            "edge term: how far the pixel leaves its own side's line, not a part of the step");
    v.Field("unmix_edges", o.uncertainty.unmix_edges,
            "an edge pixel whose phasor, where it can tell, does not show (min_jump_sigma) most "
            "of its area on its own side is charged the whole step");
    v.Field("unknown_neighbour_flags", FlagMask{o.uncertainty.unknown_neighbour_flags},
            "a pixel next to one with any of these flags is flagged");
    v.Field("judge_combination", o.uncertainty.judge_combination,
            "with prediction.combine: judge the delivered combination, not the reading");
  });
  v.Section("prediction",
            "each pixel's distance predicted by its neighbours: the uncertainty judges the "
            "reading's residual (not in the paper)",
            [&] {
              v.Field("enabled", o.prediction_enabled, "needs accuracy.enabled");
              v.Field("radius_px", o.prediction.radius_px, "largest window half-size, [1, 5]");
              v.Field("max_disagreement_sigma", o.prediction.max_disagreement_sigma,
                      "a window's pairs must agree within this many σ, (0, 100]");
              v.Field("min_pairs", o.prediction.min_pairs,
                      "usable pairs a window needs, [1, 2 R (R + 1)]: 24 at radius 3");
              v.Field("combine", o.prediction_combine,
                      "deliver kept pixels as the combination of reading and prediction");
            });
  v.Section("denoise",
            "ΔL-weighted mean of each pixel's own surface before the pair and the neighbourhood "
            "filters (not in the paper)",
            [&] {
              v.Field("enabled", o.denoise_enabled, "needs accuracy.enabled");
              v.Field("radius_px", o.denoise.radius_px, "window half-size, [1, 3]");
              v.Field("support_sigma", o.denoise.support_sigma,
                      "neighbours within this many combined σ, (0, 100]");
              v.Field("max_step_m", o.denoise.max_step_m,
                      "m, [0, 1e6]: neighbours within this of the centre too; 0 = no limit");
              v.Field("fit_plane", o.denoise.fit_plane,
                      "the support's fitted plane at the centre instead of its mean");
            });
  v.Section("smoothing", "edge-preserving spatial smoothing of kept distances (not in the paper)",
            [&] {
              v.Field("enabled", o.smoothing_enabled, "");
              v.Field("kind", o.smoothing.kind, "median or bilateral (weighted by ΔL)");
              v.Field("radius_px", o.smoothing.radius_px, "window half-size, [1, 3]");
              v.Field("max_jump_m", o.smoothing.max_jump_m,
                      "m, >= 0: support within this of the centre; 0 = no limit");
              v.Field("min_support", o.smoothing.min_support, "pixels incl. the centre, [1, 49]");
              v.Field("range_sigma_factor", o.smoothing.range_sigma_factor,
                      "bilateral: range weight width in σ, (0, 100]");
              v.Field("fallback_sigma_m", o.smoothing.fallback_sigma_m,
                      "bilateral: σ where ΔL is missing, m, > 0");
            });
  v.Section("temporal", "per-pixel average over frames, weighted by ΔL, reset on motion", [&] {
    v.Field("enabled", o.temporal_enabled, "");
    v.Field("reset_sigma", o.temporal.reset_sigma, "motion test in σ, (0, 100]");
    v.Field("drift_sigma", o.temporal.drift_sigma, "drift test in σ, (0, reset_sigma]");
    v.Field("drift_frames", o.temporal.drift_frames, "frames of one-signed drift, [2, 100]");
    v.Field("max_frames", o.temporal.max_frames, "longest effective average, [1, 10000]");
    v.Field("max_gap_frames", o.temporal.max_gap_frames,
            "rejected frames before a pixel is forgotten, [0, 255]");
    v.Field("fallback_sigma_m", o.temporal.fallback_sigma_m, "σ where ΔL is missing, m, > 0");
  });
  v.Section(
      "frame_pair",
      "consecutive frames combined: dual-frequency unwrapping or HDR (not in the paper)", [&] {
        v.Field("enabled", o.frame_pair_enabled, "needs accuracy.enabled");
        v.Field("alternate_modulation_frequency_hz", o.alternate_modulation_frequency_hz,
                "Hz; 0 = do not alternate; e.g. 17000000 with a 20 MHz camera");
        v.Field("hdr_exposure_ratio", o.hdr_exposure_ratio,
                "0 = off; else every other frame this many times longer, [1.5, 64]");
        v.Field("max_range_m", o.frame_pair.max_range_m, "m, (0, 1000]");
        v.Field("max_disagreement_sigma", o.frame_pair.max_disagreement_sigma,
                "kInconsistent beyond this many combined σ, (0, 1000]");
        v.Field("min_tolerance_m", o.frame_pair.min_tolerance_m, "m, [0, 10]");
        v.Field("max_amplitude_ratio", o.frame_pair.max_amplitude_ratio,
                "amplitude per µs change beyond which a pixel moved; 0 = off, [1, 1e6]");
        v.Field("max_amplitude_disagreement_sigma", o.frame_pair.max_amplitude_disagreement_sigma,
                "two frequencies: amplitude disagreement (σ of ln A) beyond which a pixel "
                "sums two returns; 0 = off, [0, 1000]");
        v.Field("min_amplitude_tolerance", o.frame_pair.min_amplitude_tolerance,
                "floor of that tolerance, relative amplitude, [0, 1]");
        v.Field("max_motion_m", o.frame_pair.max_motion_m,
                "two frequencies: a disagreement up to this that leaves the wrap count certain "
                "is motion (the current reading is kept); 0 = off, m, [0, 10]");
        v.Field("two_returns_radius_px", o.frame_pair.two_returns_radius_px,
                "two frequencies: window half-size over which the two-returns check also pools "
                "amplitude ratio and distance difference (multipath over regions); 0 = per pixel "
                "only, [0, 5]; 0 with denoise");
      });
  v.Section("controller", "Stage 4: integration time; frame t sets frame t + 1", [&] {
    v.Field("enabled", o.controller_enabled, "off: the register is left alone");
    v.Field("kind", o.controller.kind,
            "may-proportional, may-incremental, vendor-histogram, fixed or model-based");
    v.Field("target_intensity",
            Measured<double>{o.controller.target_intensity, defaults.controller.target_intensity},
            "I_A, register units, (0, 65532]; left out: the calibration's set point");
    v.Field("gain_register_per_intensity",
            Measured<double>{o.controller.gain_register_per_intensity,
                             defaults.controller.gain_register_per_intensity},
            "V_p, registers per intensity unit, [0, 1], 0 = scheduled (loop_gain c_t / I_t); left "
            "out: the calibration's set point");
    v.Field("bias_register",
            Measured<int>{o.controller.bias_register, defaults.controller.bias_register},
            "c_0, [min_register, max_register]; also the first frame's register; left out: the "
            "calibration's set point");
    v.Field("loop_gain", o.controller.loop_gain,
            "loop gain of the scheduled V_p (when gain_register_per_intensity is 0), (0, 1]");
    v.Field("frame_rate_hz", o.controller.frame_rate_hz,
            "Hz, >= 0: the integration time leaves this frame rate; 0 = the camera's maximum");
    v.Field("min_register", o.controller.min_register, "[1, max_register]");
    v.Field("max_register", o.controller.max_register, "[min_register, 65535]");
    v.Section("roi", "pixels the mean intensity is taken over; rows or cols 0 = whole image", [&] {
      v.Field("row", o.controller.roi.row, "top row, >= 0");
      v.Field("col", o.controller.roi.col, "left column, >= 0");
      v.Field("rows", o.controller.roi.rows, ">= 0");
      v.Field("cols", o.controller.roi.cols, ">= 0");
    });
    v.Field("exclude_flags", FlagMask{o.controller.exclude_flags},
            "pixels with these flags do not count ...");
    v.Field("clipped_intensity", o.controller.clipped_intensity,
            "... unless their intensity is at least this (clipped), [0, 65532]; 0 = off");
    v.Field("percent_over_pos", o.controller.percent_over_pos,
            "vendor-histogram: % of pixels above x, [0, 100)");
    v.Field("desired_pos", o.controller.desired_pos, "vendor-histogram: 8-bit set point, [1, 255]");
    v.Field("vendor_gain", o.controller.vendor_gain, "vendor-histogram: step fraction, (0, 1]");
    v.Field("vendor_max_step_register", o.controller.vendor_max_step_register,
            "vendor-histogram: largest step, >= 1");
    v.Field("vendor_deadband", o.controller.vendor_deadband, "vendor-histogram: [0, 254]");
    v.Field("max_clipped_fraction", o.controller.max_clipped_fraction,
            "model-based: fraction of ROI pixels allowed to clip, [0, 0.5]");
    v.Field("model_headroom", o.controller.model_headroom,
            "model-based: bright quantile at this fraction of full scale, (0, 1]");
    v.Field("model_max_increase", o.controller.model_max_increase,
            "model-based: largest factor up per frame, [1, 1000]");
    v.Field("model_backoff", o.controller.model_backoff,
            "model-based: factor down when too many pixels clip, (1, 1000]");
    v.Field("model_deadband", o.controller.model_deadband,
            "model-based: smallest relative change made, [0, 0.5]");
  });
  v.Section("point_cloud", "Stage 6: organised cloud in the camera frame", [&] {
    v.Field("enabled", o.cloud_enabled, "");
    v.Field("nan_flags", FlagMask{o.cloud.nan_mask}, "points with these flags get NaN x, y, z");
  });
  v.Section("false_color", "Stage 7: display (section III-A)", [&] {
    v.Field("near_m", o.color.near_m, "distance shown yellow, m, >= 0");
    v.Field("far_m", o.color.far_m, "distance shown blue, m, > near_m; 0 = L");
    v.Field("out_of_range_black", o.color.out_of_range_black, "");
    v.Field("amplitude_shading", o.color.amplitude_shading, "");
    v.Field("shading_reference_amplitude", o.color.shading_reference_amplitude,
            "register units, > 0");
    v.Field("shading_min_value", o.color.shading_min_value, "[0, 1]");
    v.Field("legend", o.color_legend, "append the legend bar");
  });
  v.Section("stats", "per-frame statistics against ground truth", [&] {
    v.Field("bad_error_m", o.stats.bad_error_m, "a pixel is bad beyond this error, m, (0, 100]");
  });
}

// --- Writer ----------------------------------------------------------------------------------

std::string FormatDouble(double value) {
  if (std::isnan(value)) return ".nan";
  if (std::isinf(value)) return value > 0 ? ".inf" : "-.inf";
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  std::string text(buffer, result.ptr);
  // "1e-05" is a string in YAML 1.1 core schemas that lack the dot; yaml-cpp reads it as a
  // number either way, but an explicit ".0" keeps floats recognisable to other readers.
  if (text.find_first_of(".eEn") == std::string::npos) text += ".0";
  return text;
}

std::string Quote(const std::string& text) {
  std::string out = "\"";
  for (const char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

class Writer {
 public:
  explicit Writer(const std::set<std::string>* given_keys) : given_keys_(given_keys) {}

  template <typename F>
  void Section(const char* key, const char* doc, F&& body) {
    Line(key + std::string(":"), doc);
    path_.push_back(key);
    ++depth_;
    body();
    --depth_;
    path_.pop_back();
  }
  void Field(const char* key, bool& value, const char* doc) {
    Scalar(key, value ? "true" : "false", doc);
  }
  void Field(const char* key, int& value, const char* doc) {
    Scalar(key, std::to_string(value), doc);
  }
  void Field(const char* key, double& value, const char* doc) {
    Scalar(key, FormatDouble(value), doc);
  }
  void Field(const char* key, std::string& value, const char* doc) {
    Scalar(key, Quote(value), doc);
  }
  void Field(const char* key, ControllerKind& value, const char* doc) {
    Scalar(key, std::string(ControllerKindName(value)), doc);
  }
  void Field(const char* key, SpatialFilterKind& value, const char* doc) {
    Scalar(key, std::string(SpatialFilterKindName(value)), doc);
  }
  template <typename T>
  void Field(const char* key, Measured<T> m, const char* doc) {
    if (m.value != m.default_value || Given(key)) {
      Field(key, m.value, doc);
      return;
    }
    // Commented out: the default applies when nothing was measured.
    const std::size_t at = text.size();
    Field(key, m.value, doc);
    text.insert(at + static_cast<std::size_t>(depth_) * 2, "# ");
  }
  void Field(const char* key, FlagMask mask, const char* doc) {
    std::string list;
    for (const Flag f : kAllFlags) {
      if (!PixelFlags(mask.bits).Has(f)) continue;
      if (!list.empty()) list += ", ";
      list += FlagName(f);
    }
    Scalar(key, "[" + list + "]", doc);
  }

  std::string text;

 private:
  void Scalar(const char* key, const std::string& value, const char* doc) {
    Line(std::string(key) + ": " + value, doc);
  }
  void Line(const std::string& content, const char* doc) {
    text.append(static_cast<std::size_t>(depth_) * 2, ' ');
    text += content;
    if (doc != nullptr && *doc != '\0') {
      text += "  # ";
      text += doc;
    }
    text += '\n';
  }
  // Whether the configuration the options came from gave `key` (in the current section).
  bool Given(const char* key) const {
    if (given_keys_ == nullptr) return false;
    std::string full;
    for (const std::string& section : path_) full += section + ".";
    return given_keys_->count(full + key) > 0;
  }
  int depth_ = 0;
  std::vector<std::string> path_;
  const std::set<std::string>* given_keys_;
};

// --- Reader ----------------------------------------------------------------------------------

class Reader {
 public:
  Reader(const YAML::Node& root, std::string source) : source_(std::move(source)) {
    nodes_.push_back(root);
    known_.emplace_back();
  }

  template <typename F>
  void Section(const char* key, const char* /*doc*/, F&& body) {
    const YAML::Node child = Lookup(key);
    if (child && !child.IsNull() && !child.IsMap()) {
      Fail(child, std::string("'") + Path(key) + "' must be a mapping");
    }
    path_.emplace_back(key);
    nodes_.push_back(child && child.IsMap() ? child : YAML::Node());
    known_.emplace_back();
    body();
    CheckUnknownKeys();
    known_.pop_back();
    nodes_.pop_back();
    path_.pop_back();
  }

  void Field(const char* key, bool& value, const char* /*doc*/) {
    const YAML::Node node = Lookup(key);
    if (!node) return;
    bool parsed = false;
    if (!node.IsScalar() || internal::IsQuoted(node) ||
        !YAML::convert<bool>::decode(node, parsed)) {
      Fail(node, TypeMessage(key, "true or false", node));
    }
    value = parsed;
  }
  void Field(const char* key, int& value, const char* /*doc*/) {
    const YAML::Node node = Lookup(key);
    if (!node) return;
    const std::string text = node.IsScalar() ? node.Scalar() : std::string();
    long long parsed = 0;
    const auto result = std::from_chars(text.data(), text.data() + text.size(), parsed);
    if (!node.IsScalar() || internal::IsQuoted(node) || text.empty() || result.ec != std::errc() ||
        result.ptr != text.data() + text.size() || parsed < std::numeric_limits<int>::min() ||
        parsed > std::numeric_limits<int>::max()) {
      Fail(node, TypeMessage(key, "an integer", node));
    }
    value = static_cast<int>(parsed);
  }
  void Field(const char* key, double& value, const char* /*doc*/) {
    const YAML::Node node = Lookup(key);
    if (!node) return;
    double parsed = 0.0;
    if (!node.IsScalar() || internal::IsQuoted(node) ||
        !YAML::convert<double>::decode(node, parsed)) {
      Fail(node, TypeMessage(key, "a number", node));
    }
    value = parsed;
  }
  void Field(const char* key, std::string& value, const char* /*doc*/) {
    const YAML::Node node = Lookup(key);
    if (!node) return;
    if (node.IsNull()) {
      value.clear();
      return;
    }
    if (!node.IsScalar()) Fail(node, TypeMessage(key, "a string", node));
    value = node.Scalar();
  }
  template <typename T>
  void Field(const char* key, Measured<T> m, const char* doc) {
    Field(key, m.value, doc);
  }
  void Field(const char* key, ControllerKind& value, const char* /*doc*/) {
    const YAML::Node node = Lookup(key);
    if (!node) return;
    if (!node.IsScalar()) Fail(node, TypeMessage(key, "a controller name", node));
    try {
      value = ParseControllerKind(node.Scalar());
    } catch (const Error& e) {
      Fail(node, "'" + Path(key) + "': " + e.what());
    }
  }
  void Field(const char* key, SpatialFilterKind& value, const char* /*doc*/) {
    const YAML::Node node = Lookup(key);
    if (!node) return;
    if (!node.IsScalar()) Fail(node, TypeMessage(key, "a filter kind", node));
    try {
      value = ParseSpatialFilterKind(node.Scalar());
    } catch (const Error& e) {
      Fail(node, "'" + Path(key) + "': " + e.what());
    }
  }
  void Field(const char* key, FlagMask mask, const char* /*doc*/) {
    const YAML::Node node = Lookup(key);
    if (!node) return;
    if (!node.IsSequence()) Fail(node, TypeMessage(key, "a list of flag names", node));
    std::uint16_t bits = 0;
    for (const YAML::Node& item : node) {
      if (!item.IsScalar()) Fail(item, TypeMessage(key, "a list of flag names", item));
      try {
        bits =
            static_cast<std::uint16_t>(bits | static_cast<std::uint16_t>(ParseFlag(item.Scalar())));
      } catch (const Error& e) {
        Fail(item, "'" + Path(key) + "': " + e.what());
      }
    }
    mask.bits = bits;
  }

  void CheckUnknownKeys() {
    const YAML::Node& node = nodes_.back();
    if (!node || !node.IsMap()) return;
    const std::vector<std::string>& known = known_.back();
    for (auto it = node.begin(); it != node.end(); ++it) {
      const std::string key = it->first.Scalar();
      bool found = false;
      for (const std::string& k : known) found = found || k == key;
      if (found) continue;
      std::string list;
      for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
      Fail(it->first, "unknown key '" + Path(key.c_str()) + "' (known here: " + list + ")");
    }
  }

 private:
  // The child `key` of the current mapping (undefined when absent); remembers it as known.
  YAML::Node Lookup(const char* key) {
    known_.back().emplace_back(key);
    const YAML::Node& parent = nodes_.back();
    if (!parent || !parent.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
    const YAML::Node child = parent[key];
    if (child && given_ != nullptr) given_->insert(Path(key));
    return child ? child : YAML::Node(YAML::NodeType::Undefined);
  }

 public:
  void RecordGivenKeys(std::set<std::string>* given) { given_ = given; }

 private:
  std::string Path(const char* key) const {
    std::string out;
    for (const std::string& p : path_) out += p + ".";
    return out + key;
  }

  std::string TypeMessage(const char* key, const char* expected, const YAML::Node& node) const {
    std::string got = node.IsScalar()     ? "'" + node.Scalar() + "'"
                      : node.IsMap()      ? std::string("a mapping")
                      : node.IsSequence() ? std::string("a list")
                                          : std::string("nothing");
    return "'" + Path(key) + "' must be " + expected + ", got " + got;
  }

  [[noreturn]] void Fail(const YAML::Node& node, const std::string& message) const {
    throw Error(ErrorCode::kFormat,
                source_ + ":" + std::to_string(node.Mark().line + 1) + ": " + message);
  }

  std::string source_;
  std::vector<YAML::Node> nodes_;
  std::vector<std::vector<std::string>> known_;
  std::vector<std::string> path_;
  std::set<std::string>* given_ = nullptr;
};

}  // namespace

PipelineOptions ParsePipelineConfig(std::string_view yaml_text, const std::string& source,
                                    const std::filesystem::path& base_dir,
                                    std::set<std::string>* given_keys) {
  if (given_keys != nullptr) given_keys->clear();
  YAML::Node root;
  try {
    root = YAML::Load(std::string(yaml_text));
  } catch (const YAML::Exception& e) {
    throw Error(ErrorCode::kFormat,
                source + ":" + std::to_string(e.mark.line + 1) + ": not YAML: " + e.msg);
  }
  internal::RejectDuplicateKeys(root, source);
  if (root && !root.IsNull() && !root.IsMap()) {
    throw Error(ErrorCode::kFormat, source + ":" + std::to_string(root.Mark().line + 1) +
                                        ": a pipeline configuration must be a mapping");
  }
  PipelineOptions options;
  Reader reader(root.IsMap() ? root : YAML::Node(), source);
  reader.RecordGivenKeys(given_keys);
  VisitOptions(reader, options);
  reader.CheckUnknownKeys();

  for (std::string* name : {&options.calibration_file, &options.alternate_calibration_file}) {
    if (name->empty() || base_dir.empty()) continue;
    const std::filesystem::path file(*name);
    if (file.is_relative()) *name = (base_dir / file).string();
  }
  try {
    options.Validate();
  } catch (const Error& e) {
    throw Error(e.code(), source + ": " + e.what());
  }
  return options;
}

PipelineOptions LoadPipelineConfig(const std::filesystem::path& path,
                                   std::set<std::string>* given_keys) {
  const std::string text = ReadFile(path, std::size_t{1} << 20);
  return ParsePipelineConfig(text, path.string(), path.parent_path(), given_keys);
}

std::string PipelineConfigToYaml(const PipelineOptions& options,
                                 const std::set<std::string>* given_keys) {
  Writer writer(given_keys);
  writer.text =
      "# tofcam pipeline configuration (docs/pipeline.md). Keys left out keep their defaults.\n";
  PipelineOptions copy = options;  // the visitor takes references; the writer only reads
  VisitOptions(writer, copy);
  return writer.text;
}

void LoadPipelineCalibration(PipelineOptions& options, const CameraInfo& camera) {
  if (!options.calibration && !options.calibration_file.empty()) {
    options.calibration = LoadCalibration(options.calibration_file);
  }
  if (options.calibration) CheckCalibrationMatches(*options.calibration, camera);
  if (!options.alternate_calibration && !options.alternate_calibration_file.empty()) {
    options.alternate_calibration = LoadCalibration(options.alternate_calibration_file);
  }
  if (options.alternate_calibration) {
    CameraInfo alternate = camera;
    alternate.modulation_frequency_hz = options.alternate_modulation_frequency_hz;
    CheckCalibrationMatches(*options.alternate_calibration, alternate);
  }
}

}  // namespace tofcam

namespace tofcam {

MeasuredDefaults ApplyMeasuredDefaults(PipelineOptions& options,
                                       const std::set<std::string>& given_keys,
                                       std::optional<double> source_delta_l_scale,
                                       const std::string& source_note) {
  MeasuredDefaults from;
  const std::optional<OffsetCalibration>& c = options.calibration;
  if (given_keys.count("accuracy.scale")) {
    from.delta_l_scale = "the configuration (accuracy.scale)";
  } else if (c && c->noise) {
    options.accuracy.scale = c->noise->delta_l_scale;
    from.delta_l_scale = "the calibration file's noise calibration (" +
                         std::to_string(c->noise->frames) + " static frames)";
    if (c->noise->model) {
      // The fitted model replaces eq. 2; a configuration that sets accuracy.scale keeps eq. 2.
      options.accuracy.model = c->noise->model;
      from.delta_l_scale = "the calibration file's fitted noise model (" +
                           std::to_string(c->noise->frames) + " static frames; eq. 2 scale " +
                           std::to_string(c->noise->delta_l_scale) + " unused)";
    }
  } else if (source_delta_l_scale && std::isfinite(*source_delta_l_scale) &&
             *source_delta_l_scale > 0.0 && *source_delta_l_scale <= 1e6) {
    options.accuracy.scale = *source_delta_l_scale;
    from.delta_l_scale = source_note.empty() ? "the camera source" : source_note;
  } else {
    from.delta_l_scale = "the default (eq. 2 as printed); tofcam calibrate --noise measures it";
  }
  if (c && c->controller_setpoint) {
    const ControllerSetpoint& p = *c->controller_setpoint;
    bool used = false;
    if (!given_keys.count("controller.target_intensity")) {
      options.controller.target_intensity = p.target_intensity;
      used = true;
    }
    if (!given_keys.count("controller.gain_register_per_intensity")) {
      options.controller.gain_register_per_intensity = p.gain_register_per_intensity;
      used = true;
    }
    if (!given_keys.count("controller.bias_register")) {
      // The default bounds (1..255) are the SR-2's; a camera with a longer range (the set point
      // was measured on it) widens them unless the configuration set them. The pipeline clamps
      // the bounds to the camera's range anyway.
      ControllerOptions& k = options.controller;
      if (!given_keys.count("controller.min_register")) {
        k.min_register = std::min(k.min_register, std::max(1, p.bias_register));
      }
      if (!given_keys.count("controller.max_register")) {
        k.max_register = std::max(k.max_register, p.bias_register);
      }
      k.bias_register = std::clamp(p.bias_register, k.min_register, k.max_register);
      used = true;
    }
    from.controller =
        used ? "the calibration file's set point (integration-time sweep of '" + p.scene + "')"
             : "the configuration";
  } else {
    from.controller = "the configuration or the defaults";
  }
  const bool scattering_given =
      std::any_of(given_keys.begin(), given_keys.end(),
                  [](const std::string& key) { return key.rfind("scattering.", 0) == 0; });
  if (scattering_given) {
    from.scattering = "the configuration";
  } else if (c && c->scattering) {
    options.scattering_enabled = true;
    options.scattering.lobes = c->scattering->lobes;
    from.scattering = "the calibration file's point-spread (" +
                      std::to_string(c->scattering->lobes.size()) + " lobe(s), " +
                      std::to_string(c->scattering->frames) + " frames per scene)";
  } else {
    from.scattering = "none measured (tofcam calibrate --scattering-target measures it)";
  }
  options.Validate();
  return from;
}

}  // namespace tofcam

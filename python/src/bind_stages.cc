// The pipeline's stages one by one, as functions on MetricFrames (tofcam.filters wraps them to
// take arrays too), and the integration-time controllers. Options come from keyword arguments
// parsed through the configuration file's reader: the same names, units and validation.

#include <pybind11/stl.h>

#include <memory>
#include <optional>

#include "arrays.h"
#include "bindings.h"
#include "options.h"
#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/color/false_color.h"
#include "tofcam/control/integration_time_controller.h"
#include "tofcam/filters/filter_set.h"
#include "tofcam/filters/flying_pixel_filter.h"
#include "tofcam/filters/jump_edge_filter.h"
#include "tofcam/filters/pixel_filters.h"
#include "tofcam/filters/weingarten_cell_filter.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam::python {
namespace {

// Options of one configuration section from keyword arguments, e.g. Section("filters",
// "jump_edge", {max_angle_deg: 150}) parses {filters: {jump_edge: {max_angle_deg: 150}}}.
PipelineOptions Section(const char* section, const char* subsection, const py::dict& kwargs) {
  py::dict inner = kwargs;
  py::dict d;
  if (subsection != nullptr) {
    py::dict sub;
    sub[subsection] = inner;
    d[section] = sub;
  } else {
    d[section] = inner;
  }
  return OptionsFromDict(d, std::string("<") + section +
                                (subsection ? std::string(".") + subsection : std::string()) + ">")
      .options;
}

RayTable Rays(const MetricFrame& frame, const std::optional<CameraIntrinsics>& intrinsics) {
  if (!intrinsics) {
    throw py::value_error("this filter needs the camera's intrinsics (intrinsics=...)");
  }
  if (intrinsics->width != frame.width() || intrinsics->height != frame.height()) {
    throw Error(ErrorCode::kMismatch, "intrinsics are " + std::to_string(intrinsics->width) + "x" +
                                          std::to_string(intrinsics->height) + ", the frame " +
                                          std::to_string(frame.width()) + "x" +
                                          std::to_string(frame.height()));
  }
  return MakeRayTable(*intrinsics);
}

void RequireDistance(const MetricFrame& f) {
  if (f.radial_distance_m.empty()) throw py::value_error("the frame has no distances");
}

py::object RunFilter(const std::string& name, const MetricFrame& frame,
                     const std::optional<CameraIntrinsics>& intrinsics, const py::dict& kwargs) {
  RequireDistance(frame);
  if (kwargs.contains("enabled")) {
    throw py::type_error("filters." + name + ": 'enabled' is not an option of the function");
  }
  const FilterSetOptions f = Section("filters", name.c_str(), kwargs).filters;
  Image<PixelFlags> out;
  if (name == "range") {
    out = RangeFilter(frame, f.range);
  } else if (name == "amplitude") {
    out = AmplitudeThresholdFilter(frame, f.amplitude);
  } else if (name == "saturation") {
    out = SaturationFilter(frame, f.saturation);
  } else if (name == "accuracy") {
    if (frame.delta_l_m.empty()) {
      throw py::value_error("filters.accuracy needs delta_l_m (compute it with tofcam.delta_l)");
    }
    out = AccuracyThresholdFilter(frame, f.accuracy);
  } else if (name == "flying_pixel") {
    out = FlyingPixelFilter(frame, f.flying_pixel);
  } else {
    const RayTable rays = Rays(frame, intrinsics);
    py::gil_scoped_release release;
    if (name == "jump_edge") {
      out = JumpEdgeFilter(frame, rays, f.jump_edge);
    } else if (name == "weingarten") {
      out = WeingartenCellFilter(frame, rays, f.weingarten);
    } else {
      throw py::value_error("unknown filter '" + name + "'");
    }
  }
  return Own(std::move(out));
}

// A controller owned by Python, with its options' description.
struct PyController {
  std::unique_ptr<IntegrationTimeController> controller;
  ControllerOptions options;
};

void BindFunctions(py::module_& m) {
  m.def(
      "to_metric",
      [](const Frame& frame, bool remove_distance_offset_register) {
        MetricConversionOptions o;
        o.remove_distance_offset_register = remove_distance_offset_register;
        return std::make_shared<MetricFrame>(ConvertToMetric(frame, o));
      },
      py::arg("frame"), py::arg("remove_distance_offset_register") = true,
      "Stage 1: registers to metres (MetricFrame; amplitude-0 pixels are flagged invalid).");
  m.def(
      "delta_l",
      [](const MetricFrame& frame, const py::kwargs& kwargs) {
        const AccuracyOptions o = Section("accuracy", nullptr, kwargs).accuracy;
        return Own(ComputeDeltaL(frame, o));
      },
      py::arg("frame"),
      "Stage 3: predicted inaccuracy ΔL = L/sqrt(8) * sqrt(I)/(2A) (paper eq. 2), m, as float32 "
      "(H, W); options: scale, intensity_per_amplitude (amplitude-only form without "
      "intensity). Pixels with amplitude 0 get inf.");
  m.def(
      "apply_calibration",
      [](const MetricFrame& frame, const OffsetCalibration& calibration) {
        return std::make_shared<MetricFrame>(ApplyCalibration(frame, calibration));
      },
      py::arg("frame"), py::arg("calibration"),
      "Stage 2: the per-pixel offsets of eq. 1, l = (m - o + L) mod L (and the distance "
      "correction when the calibration has one).");
  m.def("_filter", &RunFilter, py::arg("name"), py::arg("frame"), py::arg("intrinsics"),
        py::arg("options"));
  m.def(
      "apply_filters",
      [](const MetricFrame& frame, const CameraIntrinsics& intrinsics, const py::kwargs& kwargs) {
        RequireDistance(frame);
        const FilterSetOptions o = Section("filters", nullptr, kwargs).filters;
        const RayTable rays = Rays(frame, intrinsics);
        py::gil_scoped_release release;
        Image<PixelFlags> flags = ApplyFilters(frame, rays, o);
        py::gil_scoped_acquire acquire;
        return Own(std::move(flags));
      },
      py::arg("frame"), py::arg("intrinsics"),
      "Stage 5: every enabled filter (keyword arguments are sections of the 'filters' "
      "configuration, e.g. jump_edge={'enabled': True}); returns the filters' uint16 flags.");
  m.def(
      "point_cloud",
      [](const MetricFrame& frame, const CameraIntrinsics& intrinsics,
         std::optional<std::vector<Flag>> nan_flags) {
        RequireDistance(frame);
        PointCloudOptions o;
        if (nan_flags) {
          o.nan_mask = 0;
          for (Flag f : *nan_flags) o.nan_mask |= static_cast<std::uint16_t>(f);
        }
        const RayTable rays = Rays(frame, intrinsics);
        return std::make_shared<PointCloud>(MakePointCloud(frame, rays, o));
      },
      py::arg("frame"), py::arg("intrinsics"), py::arg("nan_flags") = py::none(),
      "Stage 6: organised PointCloud; points with any of `nan_flags` (default: every reject "
      "bit) are NaN.");
  m.def(
      "false_color",
      [](const MetricFrame& frame, bool legend, const py::kwargs& kwargs) {
        RequireDistance(frame);
        py::dict d = kwargs;
        const PipelineOptions o = Section("false_color", nullptr, d);
        Image<Rgb8> image = FalseColor(frame, o.color);
        if (legend) {
          const double far = o.color.far_m > 0.0
                                 ? o.color.far_m
                                 : UnambiguousRangeM(frame.info.modulation_frequency_hz);
          image = AddLegend(image, o.color.near_m, far);
        }
        return Own(std::move(image));
      },
      py::arg("frame"), py::arg("legend") = false,
      "Stage 7: the paper's HSV false colour (yellow near, through red and magenta, to blue "
      "far) as uint8 (H, W, 3); rejected pixels black. Options as the 'false_color' "
      "configuration section: near_m, far_m (0 = L), out_of_range_black, amplitude_shading, "
      "...");
  m.def(
      "fit_delta_l_scale",
      [](const std::vector<std::shared_ptr<MetricFrame>>& frames) {
        std::vector<MetricFrame> fs;
        fs.reserve(frames.size());
        for (const auto& f : frames) {
          if (!f)
            throw py::type_error("fit_delta_l_scale: frames must be tofcam.MetricFrame objects");
          fs.push_back(*f);
        }
        const DeltaLScaleFit fit = FitDeltaLScale(fs);
        py::dict d;
        d["scale"] = fit.scale;
        d["median_ratio"] = fit.median_ratio;
        d["r_squared"] = fit.r_squared;
        d["relative_rms"] = fit.relative_rms;
        d["pixels_used"] = fit.pixels_used;
        d["frames"] = fit.frames;
        return d;
      },
      py::arg("frames"),
      "Noise calibration: σ = scale x ΔL fitted on static frames (all at one integration time) "
      "against each pixel's temporal σ.");

  py::class_<PyController>(
      m, "Controller",
      "An integration-time controller: update(frame t) returns the register for frame t + 1.")
      .def(py::init([](const std::string& kind, const py::kwargs& kwargs) {
             py::dict d = kwargs;
             d["kind"] = kind;
             PyController c;
             c.options = Section("controller", nullptr, d).controller;
             c.controller = MakeController(c.options);
             return c;
           }),
           py::arg("kind") = "may-proportional",
           "kind: 'may-proportional' (the paper's printed law), 'may-incremental', "
           "'vendor-histogram', 'fixed' or 'model-based'; options as the 'controller' "
           "configuration section "
           "(target_intensity, gain_register_per_intensity, bias_register, min_register, ...).")
      .def(
          "update", [](PyController& c, const MetricFrame& f) { return c.controller->Update(f); },
          py::arg("frame"), "Consumes frame t (metric, flags set); returns the next register.")
      .def(
          "reset", [](PyController& c, int reg) { c.controller->Reset(reg); }, py::arg("register"),
          "Forgets the history, continuing from `register`.")
      .def_property_readonly(
          "name", [](const PyController& c) { return std::string(c.controller->Name()); })
      .def_property_readonly("initial_register",
                             [](const PyController& c) { return c.options.bias_register; })
      .def("__repr__", [](const PyController& c) {
        return Repr("Controller", {"kind='" + std::string(c.controller->Name()) + "'"});
      });
  m.def(
      "mean_control_intensity",
      [](const MetricFrame& frame, std::uint16_t exclude_flags, double clipped_intensity) {
        return MeanControlIntensity(frame, RegionOfInterest{}, exclude_flags, clipped_intensity);
      },
      py::arg("frame"), py::arg("exclude_flags") = static_cast<std::uint16_t>(Flag::kInvalid),
      py::arg("clipped_intensity") = 64221.0,
      "Mean intensity Ī over the pixels a controller counts, register units.");
}

}  // namespace

void BindStages(py::module_& m) { BindFunctions(m); }

}  // namespace tofcam::python

// The pipeline, its options as a dict / YAML (one source of truth: the configuration file's
// layout in tofcam/io/pipeline_config.h), results and statistics.

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <memory>
#include <regex>
#include <set>

#include "arrays.h"
#include "bindings.h"
#include "options.h"
#include "tofcam/core/error.h"
#include "tofcam/io/importers.h"
#include "tofcam/io/pipeline_config.h"
#include "tofcam/pipeline/pipeline.h"

namespace tofcam::python {

// --- dict <-> YAML ----------------------------------------------------------------------------

namespace {

// `out=` is filled in place only when this frame has its size and channels and the pipeline
// keeps the channels it has (Pipeline::Process); otherwise Process would replace a buffer that
// a NumPy view of `out` may still point into. A never-filled result takes any frame.
void CheckReusable(const Pipeline& pipeline, const Frame& frame, const PipelineResult& out) {
  const MetricFrame& m = out.frame;
  const bool fresh = m.radial_distance_m.empty() && m.amplitude.empty() && m.intensity.empty() &&
                     m.delta_l_m.empty() && m.flags.empty() && m.confidence.empty() && !m.truth &&
                     out.cloud.empty() && out.input_flags.empty() && out.filter_flags.empty();
  if (fresh) return;
  std::string other;
  if (m.radial_distance_m.empty()) {
    other = "channel set (channels set by hand, no distances)";
  } else if (m.width() != frame.width() || m.height() != frame.height()) {
    other = "size (" + std::to_string(m.width()) + "x" + std::to_string(m.height()) +
            ", the frame is " + std::to_string(frame.width()) + "x" +
            std::to_string(frame.height()) + ")";
  } else if (m.has_intensity() != frame.info.has_intensity) {
    other = m.has_intensity() ? "intensity channel (the frame has none)"
                              : "channel set (no intensity; the frame has one)";
  } else if (m.truth.has_value() != frame.truth.has_value()) {
    other = m.truth ? "ground truth (the frame has none)" : "channel set (no ground truth)";
  } else if (m.delta_l_m.empty() == pipeline.options().accuracy_enabled) {
    other = m.delta_l_m.empty() ? "channel set (no ΔL; this pipeline computes it)"
                                : "ΔL channel (this pipeline computes none)";
  } else if (out.cloud.empty() == pipeline.options().cloud_enabled) {
    other = out.cloud.empty() ? "channel set (no point cloud; this pipeline makes one)"
                              : "point cloud (this pipeline makes none)";
  }
  if (!other.empty()) {
    throw Error(ErrorCode::kMismatch,
                "process: out holds a result with another " + other +
                    "; its buffers cannot be reused (views of them would point at freed "
                    "memory): pass out=None or a result of this kind of frame");
  }
}

YAML::Node ToYaml(py::handle value, const std::string& path) {
  if (py::isinstance<py::dict>(value)) {
    YAML::Node node(YAML::NodeType::Map);
    for (const auto& [k, v] : py::reinterpret_borrow<py::dict>(value)) {
      if (!py::isinstance<py::str>(k)) {
        throw py::type_error("option keys must be strings (at '" + path + "')");
      }
      const std::string key = py::str(k);
      node[key] = ToYaml(v, path.empty() ? key : path + "." + key);
    }
    return node;
  }
  if (py::isinstance<py::list>(value) || py::isinstance<py::tuple>(value)) {
    YAML::Node node(YAML::NodeType::Sequence);
    for (py::handle item : value) node.push_back(ToYaml(item, path));
    return node;
  }
  if (py::isinstance<py::bool_>(value)) return YAML::Node(value.cast<bool>() ? "true" : "false");
  if (py::isinstance<py::int_>(value)) return YAML::Node(std::string(py::str(value)));
  if (py::isinstance<py::float_>(value)) {
    return YAML::Node(std::string(py::repr(value)));  // shortest round-trip digits
  }
  if (py::isinstance<py::str>(value) || py::hasattr(value, "__fspath__")) {
    YAML::Node node(std::string(py::str(py::module_::import("os").attr("fspath")(value))));
    node.SetTag("!");  // quoted: a string even when it looks like a number
    return node;
  }
  if (py::isinstance<Flag>(value)) return YAML::Node(std::string(FlagName(value.cast<Flag>())));
  // NumPy scalars (np.float32(5.5), np.int64(3), np.bool_): their Python value. Other NumPy
  // objects (arrays) stay unsupported.
  if (py::isinstance(value, py::module_::import("numpy").attr("generic"))) {
    py::object item = value.attr("item")();
    if (py::isinstance<py::bool_>(item) || py::isinstance<py::int_>(item) ||
        py::isinstance<py::float_>(item)) {
      return ToYaml(item, path);
    }
  }
  throw py::type_error("option '" + path + "' has unsupported type " +
                       std::string(py::str(py::type::of(value).attr("__name__"))));
}

py::object ToPython(const YAML::Node& node) {
  switch (node.Type()) {
    case YAML::NodeType::Map: {
      py::dict d;
      for (const auto& kv : node) d[py::str(kv.first.as<std::string>())] = ToPython(kv.second);
      return d;
    }
    case YAML::NodeType::Sequence: {
      py::list l;
      for (const auto& item : node) l.append(ToPython(item));
      return l;
    }
    case YAML::NodeType::Scalar: {
      const std::string s = node.Scalar();
      if (node.Tag() == "!") return py::str(s);  // quoted in the text
      if (s == "true") return py::bool_(true);
      if (s == "false") return py::bool_(false);
      static const std::regex kInt("[-+]?[0-9]+");
      if (std::regex_match(s, kInt)) return py::int_(py::str(s));
      try {
        std::size_t used = 0;
        const double d = std::stod(s, &used);
        if (used == s.size()) return py::float_(d);
      } catch (const std::exception&) {
      }
      return py::str(s);
    }
    default:
      return py::none();
  }
}

}  // namespace

PyPipelineOptions OptionsFromDict(const py::dict& d, const std::string& source) {
  YAML::Emitter out;
  out << ToYaml(d, "");
  PyPipelineOptions o;
  o.options = ParsePipelineConfig(d.empty() ? "" : out.c_str(), source, {}, &o.given_keys);
  return o;
}

py::dict OptionsToDict(const PyPipelineOptions& o) {
  const YAML::Node node = YAML::Load(PipelineConfigToYaml(o.options, &o.given_keys));
  return ToPython(node).cast<py::dict>();
}

namespace {

// A view of n = height x width elements of a vector owned by `owner`.
template <typename T>
py::object VectorView(std::vector<T>& v, int height, int width, py::handle owner) {
  if (v.empty() || v.size() != static_cast<std::size_t>(height) * width) return py::none();
  using E = typename Element<T>::type;
  return py::array_t<E>({height, width}, {width * py::ssize_t{sizeof(E)}, py::ssize_t{sizeof(E)}},
                        reinterpret_cast<E*>(v.data()), owner);
}

void BindOptions(py::module_& m) {
  py::class_<PyPipelineOptions>(
      m, "PipelineOptions",
      "Every pipeline option. Round-trips the YAML configuration (`tofcam run --print-config`, "
      "docs/pipeline.md): to_dict()/from_dict() and to_yaml()/from_yaml() carry exactly the "
      "same keys, units and validation.")
      .def(py::init([](const py::kwargs& sections) {
             return OptionsFromDict(py::dict(sections), "<PipelineOptions>");
           }),
           "Defaults, with whole sections given as keyword arguments, e.g. "
           "PipelineOptions(filters={'jump_edge': {'enabled': True}}).")
      .def_static(
          "from_dict",
          [](const py::dict& d) { return OptionsFromDict(d, "<PipelineOptions.from_dict>"); },
          py::arg("options"), "Options from a nested dict (keys left out keep their defaults).")
      .def_static(
          "from_yaml",
          [](const std::string& text, const std::string& source) {
            PyPipelineOptions o;
            o.options = ParsePipelineConfig(text, source, {}, &o.given_keys);
            return o;
          },
          py::arg("text"), py::arg("source") = "<yaml>",
          "Options from configuration text; errors name `source`, the line and the key.")
      .def_static(
          "load",
          [](const std::filesystem::path& path) {
            PyPipelineOptions o;
            o.options = LoadPipelineConfig(path, &o.given_keys);
            return o;
          },
          py::arg("path"), "Options from a configuration file.")
      .def("to_dict", &OptionsToDict,
           "The options as a nested dict (camera-specific keys at their defaults are left out, "
           "as in the printed configuration: they are measured per camera).")
      .def(
          "to_yaml",
          [](const PyPipelineOptions& o) { return PipelineConfigToYaml(o.options, &o.given_keys); },
          "The options as configuration text with a comment per key.")
      .def(
          "__eq__",
          [](const PyPipelineOptions& a, const PyPipelineOptions& b) {
            return PipelineConfigToYaml(a.options, &a.given_keys) ==
                   PipelineConfigToYaml(b.options, &b.given_keys);
          },
          py::is_operator())  // another type: NotImplemented, so `options == None` is False
      .def("__repr__", [](const PyPipelineOptions& o) {
        return "PipelineOptions.from_dict(" + std::string(py::repr(OptionsToDict(o))) + ")";
      });
}

void BindResults(py::module_& m) {
  py::class_<PointCloud, std::shared_ptr<PointCloud>>(
      m, "PointCloud",
      "Organised point cloud in the camera frame (x right, y down, z forward, m). x, y, z, "
      "amplitude, intensity, delta_l_m and flags are (H, W) views; rejected points are NaN.")
      .def_readonly("width", &PointCloud::width)
      .def_readonly("height", &PointCloud::height)
      .def_property_readonly("x",
                             [](py::object s) {
                               auto& c = s.cast<PointCloud&>();
                               return VectorView(c.x, c.height, c.width, s);
                             })
      .def_property_readonly("y",
                             [](py::object s) {
                               auto& c = s.cast<PointCloud&>();
                               return VectorView(c.y, c.height, c.width, s);
                             })
      .def_property_readonly("z",
                             [](py::object s) {
                               auto& c = s.cast<PointCloud&>();
                               return VectorView(c.z, c.height, c.width, s);
                             })
      .def_property_readonly("amplitude",
                             [](py::object s) {
                               auto& c = s.cast<PointCloud&>();
                               return VectorView(c.amplitude, c.height, c.width, s);
                             })
      .def_property_readonly("intensity",
                             [](py::object s) {
                               auto& c = s.cast<PointCloud&>();
                               return VectorView(c.intensity, c.height, c.width, s);
                             })
      .def_property_readonly("delta_l_m",
                             [](py::object s) {
                               auto& c = s.cast<PointCloud&>();
                               return VectorView(c.delta_l_m, c.height, c.width, s);
                             })
      .def_property_readonly("flags",
                             [](py::object s) {
                               auto& c = s.cast<PointCloud&>();
                               return VectorView(c.flags, c.height, c.width, s);
                             })
      .def(
          "xyz",
          [](const PointCloud& c) {
            py::array_t<float> out({c.height, c.width, 3});
            float* o = out.mutable_data();
            for (std::size_t i = 0; i < c.size(); ++i) {
              o[3 * i] = c.x[i];
              o[3 * i + 1] = c.y[i];
              o[3 * i + 2] = c.z[i];
            }
            return out;
          },
          "float32 (H, W, 3) copy of the coordinates, m (NaN where rejected).")
      .def(
          "valid_points",
          [](const PointCloud& c) {
            const std::size_t n = c.CountValid();
            py::array_t<float> out({static_cast<py::ssize_t>(n), py::ssize_t{3}});
            float* o = out.mutable_data();
            std::size_t k = 0;
            for (std::size_t i = 0; i < c.size(); ++i) {
              if (!c.IsValid(i)) continue;
              o[3 * k] = c.x[i];
              o[3 * k + 1] = c.y[i];
              o[3 * k + 2] = c.z[i];
              ++k;
            }
            return out;
          },
          "float32 (N, 3): the valid points in row-major pixel order, m.")
      .def("count_valid", &PointCloud::CountValid)
      .def("__len__", &PointCloud::size)
      .def("__repr__", [](const PointCloud& c) {
        return Repr("PointCloud",
                    {"width=" + std::to_string(c.width), "height=" + std::to_string(c.height),
                     "valid=" + std::to_string(c.CountValid())});
      });

  py::class_<FrameStats>(m, "FrameStats", "Per-frame statistics (docs/pipeline.md).")
      .def_readonly("sequence", &FrameStats::sequence)
      .def_readonly("timestamp_s", &FrameStats::timestamp_s)
      .def_readonly("integration_time_register", &FrameStats::integration_time_register)
      .def_readonly("integration_time_us", &FrameStats::integration_time_us)
      .def_readonly("mean_intensity", &FrameStats::mean_intensity,
                    "Mean intensity the controller sees, register units.")
      .def_readonly("pixels", &FrameStats::pixels)
      .def_readonly("kept_pixels", &FrameStats::kept_pixels)
      .def_readonly("valid_fraction", &FrameStats::valid_fraction)
      .def_readonly("mean_delta_l_m", &FrameStats::mean_delta_l_m, "Mean ΔL of kept pixels, m.")
      .def_readonly("next_integration_register", &FrameStats::next_integration_register)
      .def_readonly("has_truth", &FrameStats::has_truth)
      .def_readonly("truth_error_pixels", &FrameStats::truth_error_pixels)
      .def_readonly("rmse_m", &FrameStats::rmse_m, "RMSE of kept pixels against truth, m.")
      .def_readonly("footprint_rmse_m", &FrameStats::footprint_rmse_m,
                    "The same against the footprint truth (a pixel reading a surface inside its "
                    "own area is right), m; NaN without a footprint.")
      .def_readonly("bad_pixels", &FrameStats::bad_pixels)
      .def_readonly("bad_removed", &FrameStats::bad_removed)
      .def_readonly("good_pixels", &FrameStats::good_pixels)
      .def_readonly("good_kept", &FrameStats::good_kept)
      .def_readonly("bad_removed_fraction", &FrameStats::bad_removed_fraction)
      .def_readonly("good_kept_fraction", &FrameStats::good_kept_fraction)
      .def("__repr__", [](const FrameStats& s) {
        return Repr("FrameStats",
                    {"sequence=" + std::to_string(s.sequence),
                     "integration_time_register=" + std::to_string(s.integration_time_register),
                     "mean_intensity=" + ReprValue(s.mean_intensity),
                     "valid_fraction=" + ReprValue(s.valid_fraction),
                     "mean_delta_l_m=" + ReprValue(s.mean_delta_l_m)});
      });

  py::class_<PipelineResult, std::shared_ptr<PipelineResult>>(
      m, "PipelineResult", "Output of Pipeline.process(); arrays are views into it.")
      .def(py::init<>(), "An empty result, to pass as `out=` to Pipeline.process.")
      .def_property_readonly(
          "frame",
          [](std::shared_ptr<PipelineResult> r) {
            return std::shared_ptr<MetricFrame>(r, &r->frame);
          },
          "MetricFrame: calibrated distances, ΔL and flags after all filters.")
      .def_property_readonly(
          "input_flags",
          [](py::object s) { return View(s.cast<PipelineResult&>().input_flags, s); },
          "uint16 (H, W): flags before the filters (the 'raw' view).")
      .def_property_readonly(
          "filter_flags",
          [](py::object s) { return View(s.cast<PipelineResult&>().filter_flags, s); },
          "uint16 (H, W): flags raised by the filters alone.")
      .def_property_readonly(
          "cloud",
          [](std::shared_ptr<PipelineResult> r) -> std::shared_ptr<PointCloud> {
            if (r->cloud.empty()) return nullptr;
            return {r, &r->cloud};
          },
          "PointCloud, or None when the cloud is off.")
      .def_readonly("stats", &PipelineResult::stats)
      .def_readonly("next_integration_register", &PipelineResult::next_integration_register)
      .def("__repr__", [](const PipelineResult& r) {
        return Repr("PipelineResult",
                    {"sequence=" + std::to_string(r.stats.sequence),
                     "valid_fraction=" + ReprValue(r.stats.valid_fraction),
                     "next_integration_register=" + std::to_string(r.next_integration_register)});
      });
}

PyPipelineOptions OptionsOf(const py::object& options) {
  if (options.is_none()) return OptionsFromDict(py::dict(), "<defaults>");
  if (py::isinstance<PyPipelineOptions>(options)) return options.cast<PyPipelineOptions>();
  if (py::isinstance<py::dict>(options)) {
    return OptionsFromDict(options.cast<py::dict>(), "<options dict>");
  }
  if (py::isinstance<py::str>(options)) {
    PyPipelineOptions o;
    o.options =
        ParsePipelineConfig(options.cast<std::string>(), "<options text>", {}, &o.given_keys);
    return o;
  }
  throw py::type_error("options must be a PipelineOptions, a dict or YAML text");
}

void BindPipelineClass(py::module_& m) {
  py::class_<Pipeline, std::shared_ptr<Pipeline>>(
      m, "Pipeline",
      "The paper's pipeline for one camera: metric conversion, calibration (eq. 1), ΔL (eq. 2), "
      "filters, integration-time controller, point cloud and statistics.")
      .def(py::init([](py::object camera, py::object options, bool measured_defaults) {
             PyPipelineOptions o = OptionsOf(options);
             CameraInfo info;
             std::optional<double> source_scale;
             std::string source_note;
             if (py::isinstance<Camera>(camera)) {
               const Camera& c = camera.cast<const Camera&>();
               info = c.Info();
               if (const auto* imported = dynamic_cast<const ImportedCamera*>(&c)) {
                 source_scale = imported->delta_l_scale();
                 source_note = imported->delta_l_scale_note();
               }
             } else if (py::isinstance<CameraInfo>(camera)) {
               info = camera.cast<CameraInfo>();
             } else {
               throw py::type_error("camera must be a tofcam.Camera or a tofcam.CameraInfo");
             }
             LoadPipelineCalibration(o.options, info);
             if (measured_defaults) {
               (void)ApplyMeasuredDefaults(o.options, o.given_keys, source_scale, source_note);
             }
             return std::make_shared<Pipeline>(o.options, info);
           }),
           py::arg("camera"), py::arg("options") = py::none(), py::arg("measured_defaults") = true,
           "camera: a Camera or CameraInfo; options: PipelineOptions, a dict or YAML text. "
           "A calibration file named in the options is loaded. With measured_defaults, "
           "camera-specific values the options leave at their defaults come from the "
           "calibration (noise scale, controller set point) or, for an ImportedCamera, from "
           "the importer's noise scale (as `tofcam run` does).")
      .def(
          "process",
          [](Pipeline& p, const Frame& frame, std::shared_ptr<PipelineResult> out) {
            if (!out) {
              out = std::make_shared<PipelineResult>();
            } else {
              CheckReusable(p, frame, *out);
            }
            {
              py::gil_scoped_release release;
              p.Process(frame, *out);
            }
            return out;
          },
          py::arg("frame"), py::arg("out") = nullptr,
          "Runs every stage on a Frame (GIL released). With `out`, its buffers are reused "
          "(views of it then show the new frame); MismatchError when `out` holds a frame of "
          "another size or other channels (intensity, ground truth, ΔL, cloud). Otherwise a new "
          "PipelineResult is returned.")
      .def_property_readonly("initial_integration_register", &Pipeline::InitialIntegrationRegister,
                             "Register to set before the first frame (c_0).")
      .def("reset_controller", &Pipeline::ResetController, py::arg("register"),
           "Forgets the controller's history, continuing at `register`.")
      .def(
          "render_raw",
          [](const Pipeline& p, const PipelineResult& r) { return Own(p.RenderRaw(r)); },
          py::arg("result"),
          "uint8 (H', W, 3) false colour with only the input flags black; with the options' "
          "color_legend (default) a legend bar is appended below, so H' > H.")
      .def(
          "render_filtered",
          [](const Pipeline& p, const PipelineResult& r) { return Own(p.RenderFiltered(r)); },
          py::arg("result"),
          "uint8 (H', W, 3) false colour after the filters (legend as in render_raw).")
      .def_property_readonly(
          "options",
          [](const Pipeline& p) {
            PyPipelineOptions o;
            o.options = p.options();
            return o;
          },
          "The effective options (after calibration and camera bounds).")
      .def_property_readonly("camera", &Pipeline::camera, py::return_value_policy::copy,
                             "CameraInfo the pipeline was made for (a copy).")
      .def_property_readonly("controller_name",
                             [](const Pipeline& p) { return std::string(p.ControllerName()); })
      .def(
          "_cpp_loop_seconds",
          [](Pipeline& p, Camera& camera, int frames) {
            // The loop a C++ user writes, for the Python-overhead benchmark
            // (bench/python_bench.py): grab, process into a reused result, read a pixel.
            py::gil_scoped_release release;
            PipelineResult result;
            volatile float sink = 0.0f;
            const auto start = std::chrono::steady_clock::now();
            for (int k = 0; k < frames; ++k) {
              std::optional<Frame> frame = camera.Grab();
              if (!frame) throw Error(ErrorCode::kInvalidArgument, "the camera ended");
              p.Process(*frame, result);
              sink = sink + result.frame.radial_distance_m.data()[0];
            }
            return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
          },
          py::arg("camera"), py::arg("frames"))
      .def("__repr__", [](const Pipeline& p) {
        return Repr("Pipeline", {"camera='" + p.camera().model + "'",
                                 "controller='" + std::string(p.ControllerName()) + "'"});
      });
}

}  // namespace

void BindPipeline(py::module_& m) {
  BindOptions(m);
  BindResults(m);
  BindPipelineClass(m);
}

}  // namespace tofcam::python

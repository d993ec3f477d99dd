// Cameras (the simulator, playback of recordings, importers of real cameras) and scenes.

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <memory>

#include "arrays.h"
#include "bindings.h"
#include "tofcam/core/camera.h"
#include "tofcam/core/error.h"
#include "tofcam/io/importers.h"
#include "tofcam/io/recording.h"
#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::python {
namespace {

// Grabs with the GIL released (rendering and file reads take milliseconds).
std::shared_ptr<Frame> GrabFrame(Camera& camera) {
  std::optional<Frame> frame;
  {
    py::gil_scoped_release release;
    frame = camera.Grab();
  }
  if (!frame) return nullptr;
  return std::make_shared<Frame>(std::move(*frame));
}

// Sets the attributes of a bound options object from keyword arguments, so that every field's
// name, type check and docstring come from its def_readwrite; unknown names are TypeErrors.
void SetFields(py::object options, const py::kwargs& kwargs, const char* what) {
  for (const auto& [key, value] : kwargs) {
    const std::string name = py::str(key);
    if (name.rfind('_', 0) == 0 || !py::hasattr(options, key) ||
        py::isinstance<py::function>(options.attr(key))) {
      throw py::type_error(std::string(what) + " has no option '" + name + "'");
    }
    try {
      options.attr(key) = value;
    } catch (py::error_already_set& e) {
      // pybind's setter message ("incompatible function arguments ... arg0: int") names
      // neither the option nor the value; the option's current value shows the type it takes.
      if (!e.matches(PyExc_TypeError)) throw;
      const py::object current = options.attr(key);
      throw py::type_error(std::string(what) + " option '" + name + "' takes a " +
                           std::string(py::str(py::type::of(current).attr("__name__"))) +
                           " (in its range), got " + std::string(py::repr(value)));
    }
  }
}

sim::Scene SceneOf(const py::object& scene) {
  if (py::isinstance<sim::Scene>(scene)) return scene.cast<sim::Scene>();
  if (py::isinstance<py::str>(scene) || py::hasattr(scene, "__fspath__")) {
    const std::string spec = py::str(py::module_::import("os").attr("fspath")(scene));
    const auto [name, overrides] = sim::ParseSceneSpec(spec);
    return sim::ResolveScene(name, overrides);
  }
  throw py::type_error("scene must be a tofcam.Scene, a built-in scene name or a YAML path");
}

sim::CameraModel ModelOf(const py::object& model) {
  if (py::isinstance<sim::CameraModel>(model)) return model.cast<sim::CameraModel>();
  if (py::isinstance<py::str>(model) || py::hasattr(model, "__fspath__")) {
    return sim::ResolveCameraModel(py::str(py::module_::import("os").attr("fspath")(model)));
  }
  throw py::type_error("model must be a tofcam.CameraModel, a built-in model name or a YAML path");
}

void BindScenes(py::module_& m) {
  py::class_<sim::Scene>(m, "Scene", "A simulator scene (docs/scene-format.md).")
      .def_static(
          "builtin",
          [](const std::string& name, const py::kwargs& parameters) {
            sim::SceneOverrides overrides;
            for (const auto& [k, v] : parameters) overrides[py::str(k)] = py::str(v);
            return sim::LoadBuiltinScene(name, overrides);
          },
          py::arg("name"),
          "A built-in scene; keyword arguments override its parameters, e.g. "
          "Scene.builtin('wall', distance_m=2).")
      .def_static(
          "from_yaml",
          [](const std::string& text, const std::string& source,
             const std::filesystem::path& base_dir, const py::kwargs& parameters) {
            sim::SceneOverrides overrides;
            for (const auto& [k, v] : parameters) overrides[py::str(k)] = py::str(v);
            return sim::ParseScene(text, source, base_dir, overrides);
          },
          py::arg("text"), py::arg("source") = "<python>", py::arg("base_dir") = "",
          "Parses scene YAML; errors name `source` and the line.")
      .def_static(
          "load",
          [](const std::filesystem::path& path, const py::kwargs& parameters) {
            sim::SceneOverrides overrides;
            for (const auto& [k, v] : parameters) overrides[py::str(k)] = py::str(v);
            return sim::LoadScene(path, overrides);
          },
          py::arg("path"), "Loads a scene file.")
      .def_readonly("name", &sim::Scene::name)
      .def_readonly("duration_s", &sim::Scene::duration_s, "Length of a dynamic scene, s.")
      .def_readonly("parameters", &sim::Scene::parameters,
                    "Parameter values the scene was built with.")
      .def_readonly("ambient_irradiance_w_m2", &sim::Scene::ambient_irradiance_w_m2)
      .def_property_readonly("object_count", [](const sim::Scene& s) { return s.objects.size(); })
      .def("__repr__", [](const sim::Scene& s) {
        return Repr("Scene",
                    {"name='" + s.name + "'", "objects=" + std::to_string(s.objects.size()),
                     "duration_s=" + ReprValue(s.duration_s)});
      });
  m.def("builtin_scenes", &sim::BuiltinSceneNames, "Names of the built-in scenes.");

  py::class_<sim::CameraModel>(m, "CameraModel",
                               "A simulated camera model (scenes/cameras/*.yaml).")
      .def_static("builtin", &sim::ResolveCameraModel, py::arg("name"),
                  "A built-in model ('sr2', 'sr3000', 'sr4000', 'generic640x480') or a YAML path.")
      .def_static("from_yaml", &sim::ParseCameraModel, py::arg("text"),
                  py::arg("source") = "<python>", "Parses a camera model.")
      .def("with_resolution", &sim::WithResolution, py::arg("width"), py::arg("height"),
           "The same model at another resolution (field of view kept).")
      .def_readonly("name", &sim::CameraModel::name)
      .def_readonly("intrinsics", &sim::CameraModel::intrinsics)
      .def_readonly("modulation_frequencies_hz", &sim::CameraModel::modulation_frequencies_hz)
      .def_readonly("max_frame_rate_hz", &sim::CameraModel::max_frame_rate_hz)
      .def("__repr__", [](const sim::CameraModel& c) {
        return Repr("CameraModel",
                    {"name='" + c.name + "'", "width=" + std::to_string(c.intrinsics.width),
                     "height=" + std::to_string(c.intrinsics.height)});
      });
  m.def("builtin_camera_models", &sim::BuiltinCameraModelNames,
        "Names of the built-in camera models.");
}

void BindSimulatorOptions(py::module_& m) {
  using O = sim::SimulatorOptions;
  py::class_<O>(m, "SimulatorOptions",
                "Which simulator effects run and how (defaults: every physical effect on; "
                "interreflection and the planar shortcut off). Every field is "
                "also a keyword argument of SimulatedCamera.")
      .def(py::init([](const py::kwargs& kwargs) {
             py::object o = py::cast(O{});
             SetFields(o, kwargs, "SimulatorOptions");
             return o.cast<O>();
           }),
           "Options with defaults, fields set from keyword arguments.")
      .def_static("ideal", &O::Ideal, "All effects off except the ideal sensor.")
      .def_readwrite("seed", &O::seed, "Noise seed; the same seed gives bit-identical frames.")
      .def_readwrite("supersampling", &O::supersampling, "S x S rays per pixel, 1..8.")
      .def_readwrite("threads", &O::threads, "Worker threads, 1..64.")
      .def_readwrite("real_time", &O::real_time, "grab() waits for the frame time.")
      .def_readwrite("power_on_time_s", &O::power_on_time_s, "Time the camera has been on, s.")
      .def_readwrite("integration_time_register", &O::integration_time_register,
                     "Register at open; 0 = the model's default.")
      .def_readwrite("shot_noise", &O::shot_noise)
      .def_readwrite("read_noise", &O::read_noise)
      .def_readwrite("dark_current", &O::dark_current)
      .def_readwrite("saturation", &O::saturation)
      .def_readwrite("blooming", &O::blooming)
      .def_readwrite("background_light", &O::background_light)
      .def_readwrite("glossy", &O::glossy)
      .def_readwrite("multipath", &O::multipath)
      .def_readwrite("scattering", &O::scattering)
      .def_readwrite("wiggling", &O::wiggling)
      .def_readwrite("fixed_pattern", &O::fixed_pattern)
      .def_readwrite("warmup_drift", &O::warmup_drift)
      .def_readwrite("exposure_offset", &O::exposure_offset)
      .def_readwrite("motion", &O::motion)
      .def_readwrite("max_bounces", &O::max_bounces, "Mirror bounces per ray, 0..8.")
      .def_readwrite("interreflection", &O::interreflection, "One-bounce diffuse inter-reflection.")
      .def_readwrite("interreflection_samples", &O::interreflection_samples, "1..256.")
      .def_readwrite("planar_shortcut", &O::planar_shortcut,
                     "Subsample rays in closed form on the plane their pixel centres hit (faster; "
                     "frames equal to the exact ones up to rounding).")
      .def_readwrite("motion_threshold_m", &O::motion_threshold_m, "m.")
      .def_readwrite("truth_mixed_span_m", &O::truth_mixed_span_m, "m.")
      .def_readwrite("truth_bias_m", &O::truth_bias_m, "m.")
      .def("validate", &O::Validate)
      .def("__repr__", [](const O& o) {
        return Repr("SimulatorOptions", {"seed=" + std::to_string(o.seed),
                                         "supersampling=" + std::to_string(o.supersampling),
                                         "threads=" + std::to_string(o.threads)});
      });
}

void BindCameras(py::module_& m) {
  py::class_<Camera, std::shared_ptr<Camera>>(
      m, "Camera",
      "A continuous-wave ToF camera. grab() returns the next Frame or None at the end of a "
      "finite source; iterating a camera grabs until the end.")
      .def("grab", &GrabFrame, "The next frame (GIL released while grabbing), or None at the end.")
      .def_property_readonly("info", &Camera::Info, py::return_value_policy::copy,
                             "CameraInfo (a copy: changing it does not change the camera).")
      .def_property("integration_time_register", &Camera::IntegrationTimeRegister,
                    &Camera::SetIntegrationTimeRegister,
                    "Register for the next frame, in [info.min_integration_register, "
                    "info.max_integration_register].")
      .def_property("modulation_frequency_hz", &Camera::ModulationFrequencyHz,
                    &Camera::SetModulationFrequencyHz, "Hz; valid values depend on the model.")
      .def_property("distance_offset_register", &Camera::DistanceOffsetRegister,
                    &Camera::SetDistanceOffsetRegister)
      .def_property("pan_angle_rad", &Camera::PanAngleRad, &Camera::SetPanAngleRad,
                    "Pan-unit angle, rad.")
      .def("__iter__", [](py::object self) { return self; })
      .def("__next__", [](Camera& camera) {
        std::shared_ptr<Frame> frame = GrabFrame(camera);
        if (!frame) throw py::stop_iteration();
        return frame;
      });

  py::class_<sim::SimulatedCamera, Camera, std::shared_ptr<sim::SimulatedCamera>>(
      m, "SimulatedCamera",
      "The virtual ToF camera (docs/simulator.md): ray casting through supersampled pixels, "
      "four-tap demodulation with shot and read noise, saturation, blooming, scattering, "
      "multipath, systematic errors; frames carry ground truth.")
      .def(py::init([](py::object scene, py::object model,
                       std::optional<sim::SimulatorOptions> options, const py::kwargs& kwargs) {
             py::object o = py::cast(options.value_or(sim::SimulatorOptions{}));
             SetFields(o, kwargs, "SimulatedCamera");
             sim::Scene s = SceneOf(scene);
             sim::CameraModel c = ModelOf(model);
             const auto opts = o.cast<sim::SimulatorOptions>();
             py::gil_scoped_release release;  // building the Embree scene takes a while
             return std::make_shared<sim::SimulatedCamera>(std::move(s), std::move(c), opts);
           }),
           py::arg("scene") = "wall", py::arg("model") = "sr2", py::arg("options") = py::none(),
           "scene: a Scene, a built-in name ('hand', 'pavilion?distance_m=2', ...) or a YAML "
           "path; model: a CameraModel, a built-in name or a YAML path; further keyword "
           "arguments set SimulatorOptions fields (seed=, supersampling=, threads=, ...).")
      .def_property_readonly("scene", &sim::SimulatedCamera::scene, py::return_value_policy::copy,
                             "Scene (a copy: changing it does not change the camera).")
      .def_property_readonly("model", &sim::SimulatedCamera::model, py::return_value_policy::copy,
                             "CameraModel (a copy).")
      .def_property_readonly("options", &sim::SimulatedCamera::options,
                             py::return_value_policy::copy, "SimulatorOptions (a copy).")
      .def_property_readonly("next_exposure_start_s", &sim::SimulatedCamera::NextExposureStartS,
                             "Start of the next exposure, s since the camera was opened.")
      .def_property_readonly(
          "fixed_pattern_offset_m",
          [](py::object self) {
            auto& cam = self.cast<sim::SimulatedCamera&>();
            // The map is const in C++; the view is made read-only to match.
            py::object view = View(const_cast<Image<float>&>(cam.FixedPatternOffsetM()), self);
            if (!view.is_none()) view.attr("flags").attr("writeable") = false;
            return view;
          },
          "float32 (H, W), read-only: the unit's fixed-pattern offset map, m.")
      .def("warmup_offset_m", &sim::SimulatedCamera::WarmupOffsetM, py::arg("time_s"),
           "Distance offset (m) from warm-up drift at a time since opening.")
      .def("__repr__", [](const sim::SimulatedCamera& c) {
        return Repr("SimulatedCamera",
                    {"scene='" + c.scene().name + "'", "model='" + c.model().name + "'",
                     "integration_time_register=" + std::to_string(c.IntegrationTimeRegister())});
      });

  py::class_<PlaybackCamera, Camera, std::shared_ptr<PlaybackCamera>>(
      m, "PlaybackCamera",
      "Serves a recording (HDF5, docs/recording-format.md) as a camera, frame-exactly.")
      .def(py::init([](const std::filesystem::path& path, bool real_time, double speed, bool loop) {
             PlaybackOptions o;
             o.real_time = real_time;
             o.speed = speed;
             o.loop = loop;
             o.Validate();
             return std::make_shared<PlaybackCamera>(path, o);
           }),
           py::arg("path"), py::arg("real_time") = false, py::arg("speed") = 1.0,
           py::arg("loop") = false)
      .def("seek", &PlaybackCamera::Seek, py::arg("index"),
           "Makes frame `index` the next one grab() returns.")
      .def("seek_to_time_ns", &PlaybackCamera::SeekToTimeNs, py::arg("timestamp_ns"))
      .def_property_readonly("position", &PlaybackCamera::position)
      .def("__len__", &PlaybackCamera::frame_count)
      .def("__repr__", [](const PlaybackCamera& c) {
        return Repr("PlaybackCamera", {"frames=" + std::to_string(c.frame_count()),
                                       "position=" + std::to_string(c.position())});
      });
}

// ImportedSequence in Python: the camera, the frames as a list and the noise scale.
struct PySequence {
  CameraInfo camera;
  std::vector<std::shared_ptr<Frame>> frames;
  std::optional<double> delta_l_scale;
  std::string delta_l_scale_note;
};

PySequence ToPy(ImportedSequence&& s) {
  PySequence out{std::move(s.camera), {}, s.delta_l_scale, std::move(s.delta_l_scale_note)};
  out.frames.reserve(s.frames.size());
  for (Frame& f : s.frames) out.frames.push_back(std::make_shared<Frame>(std::move(f)));
  return out;
}

// Every frame present and of the camera's size: the constructor's and the setters' check.
void CheckSequence(const CameraInfo& camera, const std::vector<std::shared_ptr<Frame>>& frames) {
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (!frames[i]) {
      throw py::type_error("frames must be tofcam.Frame objects (frame " + std::to_string(i) +
                           " is None)");
    }
    if (frames[i]->width() != camera.width() || frames[i]->height() != camera.height()) {
      throw Error(ErrorCode::kMismatch,
                  "frame " + std::to_string(i) + " is " + std::to_string(frames[i]->width()) + "x" +
                      std::to_string(frames[i]->height()) + ", the camera " +
                      std::to_string(camera.width()) + "x" + std::to_string(camera.height()));
    }
  }
}

ImportedSequence FromPy(const PySequence& s) {
  CheckSequence(s.camera, s.frames);
  ImportedSequence out{s.camera, {}, s.delta_l_scale, s.delta_l_scale_note};
  for (const auto& f : s.frames) out.frames.push_back(*f);
  return out;
}

template <typename F>
PySequence Imported(F&& import) {
  ImportedSequence s;
  {
    py::gil_scoped_release release;
    s = import();
  }
  return ToPy(std::move(s));
}

void BindImporters(py::module_& m) {
  py::class_<PySequence>(m, "ImportedSequence",
                         "A real camera's frames as an importer read them (docs/importers.md).")
      .def(py::init([](const CameraInfo& camera, std::vector<std::shared_ptr<Frame>> frames,
                       std::optional<double> delta_l_scale, const std::string& note) {
             CheckSequence(camera, frames);
             return PySequence{camera, std::move(frames), delta_l_scale, note};
           }),
           py::arg("camera"), py::arg("frames"), py::arg("delta_l_scale") = py::none(),
           py::arg("delta_l_scale_note") = "",
           "A sequence of frames to serve with ImportedCamera (e.g. frames made in Python).")
      .def_property(
          "camera", [](const PySequence& s) { return s.camera; },
          [](PySequence& s, const CameraInfo& camera) {
            CheckSequence(camera, s.frames);
            s.camera = camera;
          },
          "CameraInfo (a copy; assigning one checks the frames' size against it).")
      .def_property(
          "frames", [](const PySequence& s) { return s.frames; },
          [](PySequence& s, std::vector<std::shared_ptr<Frame>> frames) {
            CheckSequence(s.camera, frames);
            s.frames = std::move(frames);
          },
          "list of Frame: a new list each time (appending to it changes nothing); assign a "
          "list to replace the frames, checked as by the constructor.")
      .def_readwrite("delta_l_scale", &PySequence::delta_l_scale,
                     "Noise scale of the camera's ΔL where the importer knows it, else None.")
      .def_readwrite("delta_l_scale_note", &PySequence::delta_l_scale_note)
      .def("__len__", [](const PySequence& s) { return s.frames.size(); })
      .def("__repr__", [](const PySequence& s) {
        return Repr("ImportedSequence", {"model='" + s.camera.model + "'",
                                         "frames=" + std::to_string(s.frames.size())});
      });
  m.def(
      "import_sequence",
      [](const std::string& spec) { return Imported([&] { return ImportFromSpec(spec); }); },
      py::arg("spec"),
      "Imports a real camera's files by spec '<format>:<path>' (see import_formats()).");
  m.def("import_formats", &ImportFormats, "Formats import_sequence() accepts.");
  m.def(
      "import_ifm_o3d3xx",
      [](const std::filesystem::path& p) { return Imported([&] { return ImportIfmO3d3xx(p); }); },
      py::arg("path"), "ifm O3D303 HDF5 written by libo3d3xx.");
  m.def(
      "import_adi_interleaved",
      [](const std::filesystem::path& p, int w, int h) {
        return Imported([&] { return ImportAdiInterleaved(p, w, h); });
      },
      py::arg("path"), py::arg("width") = 512, py::arg("height") = 512,
      "ADI ADTF3175 interleaved frame (5 bytes per pixel).");
  m.def(
      "import_adi_raw",
      [](const std::filesystem::path& depth, const std::filesystem::path& ir, int w, int h) {
        return Imported([&] { return ImportAdiRaw(depth, ir, w, h); });
      },
      py::arg("depth_path"), py::arg("ir_path"), py::arg("width") = 512, py::arg("height") = 512,
      "ADI raw depth + IR files (uint16 LE).");
  m.def(
      "import_azure_kinect",
      [](const std::filesystem::path& depth, const std::filesystem::path& ir,
         const std::filesystem::path& calibration, int w, int h) {
        return Imported([&] { return ImportAzureKinect(depth, ir, calibration, w, h); });
      },
      py::arg("depth_path"), py::arg("ir_path"), py::arg("calibration_json"),
      py::arg("width") = 640, py::arg("height") = 576,
      "Azure Kinect raw depth + IR with the factory calibration.json.");
  m.def(
      "import_mesa_dat",
      [](const std::filesystem::path& p) { return Imported([&] { return ImportMesaDat(p); }); },
      py::arg("path"), "MESA SwissRanger sample-viewer text export.");

  py::class_<ImportedCamera, Camera, std::shared_ptr<ImportedCamera>>(
      m, "ImportedCamera", "Serves an imported sequence as a camera.")
      .def(py::init([](py::object source, bool loop) {
             if (py::isinstance<py::str>(source)) {
               const std::string spec = source.cast<std::string>();
               ImportedSequence s;
               {
                 py::gil_scoped_release release;
                 s = ImportFromSpec(spec);
               }
               return std::make_shared<ImportedCamera>(std::move(s), loop);
             }
             if (py::isinstance<PySequence>(source)) {
               return std::make_shared<ImportedCamera>(FromPy(source.cast<PySequence&>()), loop);
             }
             throw py::type_error("source must be an import spec string or an ImportedSequence");
           }),
           py::arg("source"), py::arg("loop") = false,
           "source: an import spec '<format>:<path>' or an ImportedSequence.")
      .def("__len__", &ImportedCamera::frame_count)
      .def_property_readonly("delta_l_scale", &ImportedCamera::delta_l_scale)
      .def_property_readonly("delta_l_scale_note", &ImportedCamera::delta_l_scale_note);
}

}  // namespace

void BindCamera(py::module_& m) {
  BindScenes(m);
  BindSimulatorOptions(m);
  BindCameras(m);
  BindImporters(m);
}

}  // namespace tofcam::python

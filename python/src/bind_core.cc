// Errors, pixel flags, frames and camera descriptions.

#include <pybind11/stl.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>

#include "arrays.h"
#include "bindings.h"
#include "tofcam/core/camera.h"
#include "tofcam/core/error.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/pixel_flags.h"

namespace tofcam::python {

std::string Repr(const char* name, std::initializer_list<std::string> fields) {
  std::string out = std::string(name) + "(";
  bool first = true;
  for (const std::string& f : fields) {
    out += (first ? "" : ", ") + f;
    first = false;
  }
  return out + ")";
}

std::string ReprValue(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

namespace {

// tofcam.Error and one subclass per ErrorCode, each also deriving from the built-in exception a
// Python user would catch for that kind of problem.
struct ErrorClasses {
  py::object base;
  py::object by_code[7];
};

ErrorClasses& Errors() {
  static ErrorClasses* classes = new ErrorClasses();  // lives as long as the interpreter
  return *classes;
}

py::object MakeErrorClass(py::module_& m, const char* name, const char* doc, py::handle bases) {
  const std::string qualified = std::string("tofcam.") + name;
  PyObject* cls = PyErr_NewExceptionWithDoc(qualified.c_str(), doc, bases.ptr(), nullptr);
  if (cls == nullptr) throw py::error_already_set();
  py::object object = py::reinterpret_steal<py::object>(cls);
  m.attr(name) = object;
  return object;
}

void BindErrors(py::module_& m) {
  ErrorClasses& e = Errors();
  e.base = MakeErrorClass(m, "Error",
                          "Base of every tofcam error. `code` is the C++ ErrorCode's name (e.g. "
                          "'invalid-argument'); the message is the C++ message.",
                          PyExc_Exception);
  struct Spec {
    ErrorCode code;
    const char* name;
    PyObject* builtin;
    const char* doc;
  };
  const Spec specs[] = {
      {ErrorCode::kInvalidArgument, "InvalidArgumentError", PyExc_ValueError,
       "An option or argument is outside its valid range or malformed."},
      {ErrorCode::kNotFound, "NotFoundError", PyExc_FileNotFoundError,
       "A file, scene, camera model or dataset does not exist."},
      {ErrorCode::kIo, "IoError", PyExc_OSError, "Reading or writing failed."},
      {ErrorCode::kFormat, "FormatError", PyExc_ValueError,
       "A file exists but its content is malformed, truncated or hostile."},
      {ErrorCode::kMismatch, "MismatchError", PyExc_ValueError,
       "Data is well formed but does not fit (e.g. a calibration of another camera)."},
      {ErrorCode::kUnsupported, "UnsupportedError", PyExc_NotImplementedError,
       "A valid request this build or source cannot serve."},
      {ErrorCode::kInternal, "InternalError", PyExc_RuntimeError, "A bug in tofcam."},
  };
  for (const Spec& s : specs) {
    e.by_code[static_cast<int>(s.code)] =
        MakeErrorClass(m, s.name, s.doc, py::make_tuple(e.base, py::handle(s.builtin)));
  }
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const Error& error) {
      const auto index = static_cast<std::size_t>(error.code());
      py::object cls = index < 7 ? Errors().by_code[index] : Errors().base;
      // Messages quote paths and file contents, which need not be UTF-8: undecodable bytes
      // become escapes instead of a UnicodeDecodeError in place of the tofcam error.
      const std::string what = error.what();
      py::object message = py::reinterpret_steal<py::object>(PyUnicode_DecodeUTF8(
          what.data(), static_cast<Py_ssize_t>(what.size()), "backslashreplace"));
      if (!message) throw py::error_already_set();
      py::object instance = cls(message);
      instance.attr("code") = std::string(ErrorCodeName(error.code()));
      PyErr_SetObject(cls.ptr(), instance.ptr());
    }
  });
  m.def(
      "_raise",
      [](const std::string& code, const std::string& message) {
        for (int c = 0; c < 7; ++c) {
          if (ErrorCodeName(static_cast<ErrorCode>(c)) == code) {
            throw Error(static_cast<ErrorCode>(c), message);
          }
        }
        throw py::value_error("unknown error code " + code);
      },
      "Raises the tofcam error of a code name (for tests of the mapping).");
}

void BindFlags(py::module_& m) {
  py::enum_<Flag> flag(m, "Flag", py::arithmetic(),
                       "Per-pixel problem bits (16-bit field; see docs/architecture.md).");
  for (Flag f : kAllFlags) {
    std::string name(FlagName(f));
    for (char& c : name) c = c == '-' ? '_' : static_cast<char>(std::toupper(c));
    flag.value(name.c_str(), f);
  }
  m.attr("REJECT_MASK") = kRejectMask;
  m.attr("TRUTH_MASK") = kTruthMask;
  m.def(
      "flags_to_string", [](std::uint16_t bits) { return FlagsToString(PixelFlags(bits)); },
      py::arg("bits"), "Names of the set bits joined with '|', or 'none'.");
  m.def(
      "flag_name", [](Flag f) { return std::string(FlagName(f)); }, py::arg("flag"),
      "Stable lower-case name of a flag, e.g. 'high-delta-l'.");
}

void BindInfo(py::module_& m) {
  py::class_<FrameInfo>(m, "FrameInfo", "Acquisition metadata of one frame.")
      .def(py::init<>())
      .def_readwrite("sequence", &FrameInfo::sequence, "Frame counter since the camera opened.")
      .def_readwrite("timestamp_ns", &FrameInfo::timestamp_ns,
                     "Mid-exposure time, ns since the camera opened.")
      .def_readwrite("integration_time_register", &FrameInfo::integration_time_register,
                     "Raw integration-time register (SR-2: 1..255); 0 = unknown.")
      .def_readwrite("integration_time_us", &FrameInfo::integration_time_us,
                     "Integration time, µs.")
      .def_readwrite("modulation_frequency_hz", &FrameInfo::modulation_frequency_hz,
                     "Modulation frequency, Hz (> 0).")
      .def_readwrite("pan_angle_rad", &FrameInfo::pan_angle_rad,
                     "Pan-unit angle, rad, counter-clockwise positive.")
      .def_readwrite("distance_offset_register", &FrameInfo::distance_offset_register,
                     "Camera distance-offset register.")
      .def_readwrite("camera_model", &FrameInfo::camera_model, "Model name, e.g. 'SR-2'.")
      .def_readwrite("has_intensity", &FrameInfo::has_intensity,
                     "False when the source has no intensity (offset) channel.")
      .def_readwrite("confidence_source", &FrameInfo::confidence_source,
                     "What Frame.confidence holds, one line; empty without it.")
      .def("__repr__", [](const FrameInfo& i) {
        return Repr("FrameInfo",
                    {"sequence=" + std::to_string(i.sequence),
                     "timestamp_ns=" + std::to_string(i.timestamp_ns),
                     "integration_time_register=" + std::to_string(i.integration_time_register),
                     "integration_time_us=" + ReprValue(i.integration_time_us),
                     "modulation_frequency_hz=" + ReprValue(i.modulation_frequency_hz),
                     "camera_model='" + i.camera_model + "'"});
      });

  py::class_<CameraIntrinsics>(m, "CameraIntrinsics",
                               "Pinhole intrinsics with rational Brown-Conrady distortion "
                               "(pixel-centre convention: the top-left pixel's centre is (0, 0)).")
      .def(py::init<>(), "The SwissRanger SR-2's intrinsics (160 x 124 px).")
      .def_readwrite("width", &CameraIntrinsics::width, "Pixels per row.")
      .def_readwrite("height", &CameraIntrinsics::height, "Rows.")
      .def_readwrite("fx_px", &CameraIntrinsics::fx_px, "Focal length, horizontal pixels.")
      .def_readwrite("fy_px", &CameraIntrinsics::fy_px, "Focal length, vertical pixels.")
      .def_readwrite("cx_px", &CameraIntrinsics::cx_px, "Principal point column, px.")
      .def_readwrite("cy_px", &CameraIntrinsics::cy_px, "Principal point row, px.")
      .def_readwrite("k1", &CameraIntrinsics::k1)
      .def_readwrite("k2", &CameraIntrinsics::k2)
      .def_readwrite("k3", &CameraIntrinsics::k3)
      .def_readwrite("k4", &CameraIntrinsics::k4)
      .def_readwrite("k5", &CameraIntrinsics::k5)
      .def_readwrite("k6", &CameraIntrinsics::k6)
      .def_readwrite("p1", &CameraIntrinsics::p1)
      .def_readwrite("p2", &CameraIntrinsics::p2)
      .def_static("sr2", &CameraIntrinsics::SwissRangerSr2, "The SwissRanger SR-2's intrinsics.")
      .def("validate", &CameraIntrinsics::Validate,
           "Raises InvalidArgumentError naming the field when a value is out of range.")
      .def_property_readonly("horizontal_fov_rad", &CameraIntrinsics::HorizontalFovRad)
      .def_property_readonly("vertical_fov_rad", &CameraIntrinsics::VerticalFovRad)
      .def(
          "rays",
          [](const CameraIntrinsics& k) {
            const RayTable rays = MakeRayTable(k);
            py::array_t<float> out({k.height, k.width, 3});
            auto o = out.mutable_unchecked<3>();
            for (int r = 0; r < k.height; ++r) {
              for (int c = 0; c < k.width; ++c) {
                o(r, c, 0) = rays.x(r, c);
                o(r, c, 1) = rays.y(r, c);
                o(r, c, 2) = rays.z(r, c);
              }
            }
            return out;
          },
          "Unit ray per pixel as a (height, width, 3) float32 array (point = distance x ray).")
      .def("__repr__", [](const CameraIntrinsics& k) {
        return Repr("CameraIntrinsics",
                    {"width=" + std::to_string(k.width), "height=" + std::to_string(k.height),
                     "fx_px=" + ReprValue(k.fx_px), "fy_px=" + ReprValue(k.fy_px),
                     "cx_px=" + ReprValue(k.cx_px), "cy_px=" + ReprValue(k.cy_px)});
      });

  py::class_<CameraInfo>(m, "CameraInfo", "Static description of a camera.")
      .def(py::init<>(), "The SwissRanger SR-2.")
      .def_readwrite("model", &CameraInfo::model)
      .def_readwrite("intrinsics", &CameraInfo::intrinsics)
      .def_readwrite("modulation_frequency_hz", &CameraInfo::modulation_frequency_hz, "Hz.")
      .def_readwrite("integration_time_step_us", &CameraInfo::integration_time_step_us,
                     "µs per integration-time register step.")
      .def_readwrite("integration_time_base_us", &CameraInfo::integration_time_base_us,
                     "µs at register 0.")
      .def_readwrite("min_integration_register", &CameraInfo::min_integration_register)
      .def_readwrite("max_integration_register", &CameraInfo::max_integration_register)
      .def_readwrite("max_frame_rate_hz", &CameraInfo::max_frame_rate_hz, "Hz.")
      .def_readwrite("has_intensity", &CameraInfo::has_intensity)
      .def_readwrite("has_ground_truth", &CameraInfo::has_ground_truth)
      .def_property_readonly("width", &CameraInfo::width)
      .def_property_readonly("height", &CameraInfo::height)
      .def_property_readonly("unambiguous_range_m", &CameraInfo::unambiguous_range_m,
                             "L = c / (2 f_mod), m.")
      .def("integration_time_us", &CameraInfo::IntegrationTimeUs, py::arg("register"),
           "Integration time, µs, of a register value.")
      .def("__repr__", [](const CameraInfo& c) {
        return Repr("CameraInfo",
                    {"model='" + c.model + "'", "width=" + std::to_string(c.width()),
                     "height=" + std::to_string(c.height()),
                     "modulation_frequency_hz=" + ReprValue(c.modulation_frequency_hz)});
      });
}

// Channels as properties: a getter returning a zero-copy view (None when the channel is empty)
// and a setter copying into the existing buffer (same shape, exact dtype).
// The size every channel of an object must have, (0, 0) when nothing fixes it yet.
std::pair<int, int> ChannelSize(const Frame& f) { return {f.width(), f.height()}; }
std::pair<int, int> ChannelSize(const MetricFrame& f) { return {f.width(), f.height()}; }
std::pair<int, int> ChannelSize(const GroundTruth& t) {
  return {t.radial_distance_m.width(), t.radial_distance_m.height()};
}

template <typename Class, typename T>
void Channel(py::class_<Class, std::shared_ptr<Class>>& cls, const char* name,
             Image<T> Class::*member, const char* doc) {
  cls.def_property(
      name, [member](py::object self) { return View(self.cast<Class&>().*member, self); },
      [member, name](Class& self, py::object value) {
        if (value.is_none()) {
          // Freeing the buffer would leave views of it pointing at freed memory.
          throw py::type_error(std::string(name) +
                               " cannot be removed (set to None); make a new frame without it");
        }
        Image<T>& image = self.*member;
        const auto [w, h] = ChannelSize(self);
        if (image.empty() && w > 0) {
          // A channel the object did not have yet takes the object's size, not any size.
          const py::array a =
              CheckArray(value, name, py::dtype::of<typename Element<T>::type>(),
                         DtypeName<typename Element<T>::type>(), Element<T>::kChannels);
          if (a.shape(0) != h || a.shape(1) != w) {
            throw py::value_error(std::string(name) + " has shape (" + std::to_string(a.shape(0)) +
                                  ", " + std::to_string(a.shape(1)) + "), the frame is (" +
                                  std::to_string(h) + ", " + std::to_string(w) + ")");
          }
        }
        Assign(image, value, name);
      },
      doc);
}

std::string FrameRepr(const char* name, int width, int height, const FrameInfo& info, bool truth) {
  return Repr(name, {"width=" + std::to_string(width), "height=" + std::to_string(height),
                     "sequence=" + std::to_string(info.sequence),
                     "integration_time_register=" + std::to_string(info.integration_time_register),
                     std::string("truth=") + (truth ? "True" : "False")});
}

void BindFrames(py::module_& m) {
  py::class_<GroundTruth, std::shared_ptr<GroundTruth>> truth(
      m, "GroundTruth", "Ground truth a simulator attaches to each frame.");
  Channel(truth, "radial_distance_m", &GroundTruth::radial_distance_m,
          "float32 (H, W): true radial distance along the pixel ray, m; inf where nothing is hit.");
  Channel(truth, "causes", &GroundTruth::causes,
          "uint16 (H, W): physical causes of error (Flag bits in TRUTH_MASK).");
  Channel(truth, "sigma_m", &GroundTruth::sigma_m,
          "float32 (H, W): true distance standard deviation from the shot-noise model, m.");
  Channel(truth, "footprint_near_m", &GroundTruth::footprint_near_m,
          "float32 (H, W): nearest distance hit within the pixel's footprint, m; inf where "
          "nothing is hit; None when the source does not give it.");
  Channel(truth, "footprint_far_m", &GroundTruth::footprint_far_m,
          "float32 (H, W): farthest distance hit within the pixel's footprint, m; inf where "
          "nothing is hit; None when the source does not give it.");
  truth.def("__repr__", [](const GroundTruth& t) {
    return Repr("GroundTruth", {"width=" + std::to_string(t.radial_distance_m.width()),
                                "height=" + std::to_string(t.radial_distance_m.height())});
  });

  py::class_<Frame, std::shared_ptr<Frame>> frame(
      m, "Frame",
      "One frame as the camera delivers it: 16-bit distance, amplitude and intensity registers. "
      "Channels are NumPy views sharing memory with the frame (writing to them changes it).");
  frame.def(py::init([](py::object distance, py::object amplitude, py::object intensity,
                        py::object source_flags, std::optional<FrameInfo> info) {
              auto f = std::make_shared<Frame>();
              f->distance = ToImage<std::uint16_t>(distance, "distance");
              f->amplitude = ToImage<std::uint16_t>(amplitude, "amplitude");
              if (info) f->info = *info;
              if (intensity.is_none()) {
                f->intensity = Image<std::uint16_t>(f->distance.width(), f->distance.height());
                f->info.has_intensity = false;
              } else {
                f->intensity = ToImage<std::uint16_t>(intensity, "intensity");
              }
              if (!source_flags.is_none()) {
                f->source_flags = ToImage<PixelFlags>(source_flags, "source_flags");
                if (!f->source_flags.SameSize(f->distance)) {
                  throw Error(ErrorCode::kInvalidArgument,
                              "source_flags size differs from the distance channel");
                }
              }
              ValidateFrame(*f);
              return f;
            }),
            py::arg("distance"), py::arg("amplitude"), py::arg("intensity") = py::none(),
            py::arg("source_flags") = py::none(), py::arg("info") = py::none(),
            "Builds a frame from uint16 (H, W) arrays (copied). Without intensity the frame has "
            "none (info.has_intensity = False).");
  Channel(frame, "distance", &Frame::distance,
          "uint16 (H, W): phase register, 0..65535 over [0, L).");
  Channel(frame, "amplitude", &Frame::amplitude, "uint16 (H, W): amplitude register.");
  Channel(frame, "intensity", &Frame::intensity,
          "uint16 (H, W): intensity (offset) register; zeros when info.has_intensity is False.");
  Channel(frame, "source_flags", &Frame::source_flags,
          "uint16 (H, W): problems the camera itself reports, or None.");
  Channel(frame, "confidence", &Frame::confidence,
          "float32 (H, W): the camera's own confidence (higher = better; MESA map, ADI byte), "
          "or None; info.confidence_source says what it is.");
  frame.def_readwrite("info", &Frame::info)
      .def_property_readonly(
          "truth",
          [](std::shared_ptr<Frame> self) -> std::shared_ptr<GroundTruth> {
            if (!self->truth) return nullptr;
            return {self, &*self->truth};  // shares the frame's lifetime
          },
          "GroundTruth of a simulated frame, or None.")
      .def_property_readonly("width", &Frame::width)
      .def_property_readonly("height", &Frame::height)
      .def(
          "copy", [](const Frame& f) { return std::make_shared<Frame>(f); }, "A deep copy.")
      .def("__repr__", [](const Frame& f) {
        return FrameRepr("Frame", f.width(), f.height(), f.info, f.truth.has_value());
      });

  py::class_<MetricFrame, std::shared_ptr<MetricFrame>> metric(
      m, "MetricFrame",
      "A frame in metric units with per-pixel flags, as every pipeline stage consumes it. "
      "Channels are NumPy views sharing memory with the frame.");
  metric.def(
      py::init([](py::object radial_distance_m, py::object amplitude, py::object intensity,
                  py::object flags, py::object delta_l_m, std::optional<FrameInfo> info) {
        auto f = std::make_shared<MetricFrame>();
        f->radial_distance_m = ToImage<float>(radial_distance_m, "radial_distance_m");
        const int w = f->radial_distance_m.width(), h = f->radial_distance_m.height();
        auto check = [&](const auto& image, const char* name) {
          if (!image.empty() && !image.SameSize(w, h)) {
            throw py::value_error(std::string(name) + " must have the shape of radial_distance_m");
          }
        };
        f->amplitude = ToImage<float>(amplitude, "amplitude");
        check(f->amplitude, "amplitude");
        if (!intensity.is_none()) f->intensity = ToImage<float>(intensity, "intensity");
        check(f->intensity, "intensity");
        f->flags = flags.is_none() ? Image<PixelFlags>(w, h) : ToImage<PixelFlags>(flags, "flags");
        check(f->flags, "flags");
        if (!delta_l_m.is_none()) f->delta_l_m = ToImage<float>(delta_l_m, "delta_l_m");
        check(f->delta_l_m, "delta_l_m");
        if (info) f->info = *info;
        f->info.has_intensity = !f->intensity.empty();
        return f;
      }),
      py::arg("radial_distance_m"), py::arg("amplitude"), py::arg("intensity") = py::none(),
      py::arg("flags") = py::none(), py::arg("delta_l_m") = py::none(),
      py::arg("info") = py::none(),
      "Builds a metric frame from float32 (H, W) arrays (m, register units) and uint16 "
      "flags (copied).");
  Channel(metric, "radial_distance_m", &MetricFrame::radial_distance_m,
          "float32 (H, W): radial distance along the pixel ray, m.");
  Channel(metric, "amplitude", &MetricFrame::amplitude,
          "float32 (H, W): amplitude, register units.");
  Channel(metric, "intensity", &MetricFrame::intensity,
          "float32 (H, W): intensity (offset), register units; None without an offset channel.");
  Channel(metric, "flags", &MetricFrame::flags, "uint16 (H, W): Flag bits per pixel.");
  Channel(metric, "delta_l_m", &MetricFrame::delta_l_m,
          "float32 (H, W): predicted inaccuracy ΔL (eq. 2), m; None until computed.");
  Channel(metric, "confidence", &MetricFrame::confidence,
          "float32 (H, W): the camera's own confidence (Frame.confidence), or None.");
  metric.def_readwrite("info", &MetricFrame::info)
      .def_property_readonly(
          "truth",
          [](std::shared_ptr<MetricFrame> self) -> std::shared_ptr<GroundTruth> {
            if (!self->truth) return nullptr;
            return {self, &*self->truth};
          },
          "GroundTruth of a simulated frame, or None.")
      .def_property_readonly("width", &MetricFrame::width)
      .def_property_readonly("height", &MetricFrame::height)
      .def_property_readonly("has_intensity", &MetricFrame::has_intensity)
      .def(
          "valid",
          [](const MetricFrame& f) {
            py::array_t<bool> out({f.height(), f.width()});
            bool* o = out.mutable_data();
            for (std::size_t i = 0; i < f.flags.size(); ++i) o[i] = f.flags.data()[i].Valid();
            return out;
          },
          "bool (H, W): True where no reject bit is set.")
      .def(
          "copy", [](const MetricFrame& f) { return std::make_shared<MetricFrame>(f); },
          "A deep copy.")
      .def("__repr__", [](const MetricFrame& f) {
        return FrameRepr("MetricFrame", f.width(), f.height(), f.info, f.truth.has_value());
      });
}

}  // namespace

void BindCore(py::module_& m) {
  BindErrors(m);
  BindFlags(m);
  BindInfo(m);
  BindFrames(m);
}

}  // namespace tofcam::python

// Recordings, calibration files and the calibration procedure, cloud and image writers.

#include <pybind11/functional.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <memory>

#include "arrays.h"
#include "bindings.h"
#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/io/calibration_file.h"
#include "tofcam/io/cloud_io.h"
#include "tofcam/io/png.h"
#include "tofcam/io/recording.h"

namespace tofcam::python {
namespace {

void BindRecordings(py::module_& m) {
  py::class_<RecordingMetadata>(m, "RecordingMetadata", "What a recording says about itself.")
      .def_readonly("format_version", &RecordingMetadata::format_version)
      .def_readonly("tofcam_version", &RecordingMetadata::tofcam_version)
      .def_readonly("camera", &RecordingMetadata::camera)
      .def_readonly("calibration_id", &RecordingMetadata::calibration_id)
      .def_readonly("frame_camera_model", &RecordingMetadata::frame_camera_model)
      .def_readonly("has_source_flags", &RecordingMetadata::has_source_flags)
      .def_readonly("has_ground_truth", &RecordingMetadata::has_ground_truth)
      .def_readonly("has_truth_footprint", &RecordingMetadata::has_truth_footprint);

  py::class_<RecordingWriter>(
      m, "RecordingWriter",
      "Appends frames to a new HDF5 recording (docs/recording-format.md), flushed per frame so "
      "a killed writer leaves a readable file. Use as a context manager.")
      .def(py::init([](const std::filesystem::path& path, const CameraInfo& camera,
                       int compression_level, bool flush_each_frame,
                       const std::string& calibration_id) {
             RecordingOptions o;
             o.compression_level = compression_level;
             o.flush_each_frame = flush_each_frame;
             o.calibration_id = calibration_id;
             o.Validate();
             return std::make_unique<RecordingWriter>(path, camera, o);
           }),
           py::arg("path"), py::arg("camera"), py::arg("compression_level") = 4,
           py::arg("flush_each_frame") = true, py::arg("calibration_id") = "",
           "Creates (truncates) `path`; camera: the CameraInfo of the frames.")
      .def(
          "append",
          [](RecordingWriter& w, const Frame& f) {
            py::gil_scoped_release release;
            w.Append(f);
          },
          py::arg("frame"),
          "Appends one frame (GIL released). A frame of another size or shape of channels, or "
          "with a timestamp before the previous frame's (the reader would refuse the file), is "
          "refused; the frames before stay readable.")
      .def("close", &RecordingWriter::Close, "Flushes and closes; idempotent.")
      .def("__len__", &RecordingWriter::frame_count)
      .def_property_readonly("path", &RecordingWriter::path)
      .def("__enter__", [](py::object self) { return self; })
      .def("__exit__", [](RecordingWriter& w, py::args) { w.Close(); });

  // A Python index (negative counts from the end) as a frame number; IndexError outside.
  static const auto FrameIndex = [](const RecordingReader& r, std::int64_t index) {
    const auto n = static_cast<std::int64_t>(r.frame_count());
    if (index < 0) index += n;
    if (index < 0 || index >= n) throw py::index_error("frame index out of range");
    return static_cast<std::size_t>(index);
  };
  py::class_<RecordingReader, std::shared_ptr<RecordingReader>>(
      m, "RecordingReader",
      "Random access to a recording's frames: len(), reader[i] (negative indices count from "
      "the end), iteration, info(i) without the images.")
      .def(py::init<const std::filesystem::path&>(), py::arg("path"))
      .def("__len__", &RecordingReader::frame_count)
      .def(
          "__getitem__",
          [](const RecordingReader& r, std::int64_t index) {
            const std::size_t at = FrameIndex(r, index);
            Frame f;
            {
              py::gil_scoped_release release;
              f = r.Read(at);
            }
            return std::make_shared<Frame>(std::move(f));
          },
          py::arg("index"))
      .def("__iter__",
           [](std::shared_ptr<RecordingReader> r) {
             py::module_ builtins = py::module_::import("builtins");
             // A generator over indices keeps the reader alive and reads lazily.
             py::object getitem = py::cast(r).attr("__getitem__");
             return builtins.attr("map")(getitem, builtins.attr("range")(r->frame_count()));
           })
      .def(
          "info",
          [](const RecordingReader& r, std::int64_t index) {
            return r.Info(FrameIndex(r, index));  // a copy
          },
          py::arg("index"),
          "FrameInfo of frame `index` without reading its images (a copy; negative indices "
          "count from the end, as reader[i]).")
      .def("index_at_or_after", &RecordingReader::IndexAtOrAfter, py::arg("timestamp_ns"),
           "Index of the first frame at or after a timestamp (len() if none).")
      .def_property_readonly("metadata", &RecordingReader::metadata, py::return_value_policy::copy,
                             "RecordingMetadata (a copy).")
      .def_property_readonly("path", &RecordingReader::path)
      .def("__repr__", [](const RecordingReader& r) {
        return Repr("RecordingReader", {"path='" + r.path().string() + "'",
                                        "frames=" + std::to_string(r.frame_count())});
      });
}

void BindCalibration(py::module_& m) {
  py::class_<OffsetCalibration, std::shared_ptr<OffsetCalibration>>(
      m, "OffsetCalibration",
      "The per-pixel calibration (paper section II-B, docs/calibration.md).")
      .def_readonly("camera_model", &OffsetCalibration::camera_model)
      .def_readonly("width", &OffsetCalibration::width)
      .def_readonly("height", &OffsetCalibration::height)
      .def_readonly("modulation_frequency_hz", &OffsetCalibration::modulation_frequency_hz)
      .def_readonly("integration_time_us", &OffsetCalibration::integration_time_us)
      .def_readonly("integration_time_register", &OffsetCalibration::integration_time_register)
      .def_readonly("wall_distance_m", &OffsetCalibration::wall_distance_m)
      .def_readonly("frames_averaged", &OffsetCalibration::frames_averaged)
      .def_readonly("exposure_offset_m_per_ms", &OffsetCalibration::exposure_offset_m_per_ms)
      .def_property_readonly(
          "offset_m", [](py::object s) { return View(s.cast<OffsetCalibration&>().offset_m, s); },
          "float32 (H, W): the offset matrix o of eq. 1, m.")
      .def_property_readonly(
          "pixel_flags",
          [](py::object s) { return View(s.cast<OffsetCalibration&>().pixel_flags, s); },
          "uint16 (H, W): pixels the calibration could not calibrate.")
      .def_property_readonly(
          "delta_l_scale",
          [](const OffsetCalibration& c) -> std::optional<double> {
            if (!c.noise) return std::nullopt;
            return c.noise->delta_l_scale;
          },
          "The noise calibration's ΔL scale, or None.")
      .def_property_readonly(
          "has_distance_correction",
          [](const OffsetCalibration& c) { return c.distance_correction.has_value(); })
      .def("validate", &OffsetCalibration::Validate)
      .def("__repr__", [](const OffsetCalibration& c) {
        return Repr("OffsetCalibration",
                    {"camera_model='" + c.camera_model + "'", "width=" + std::to_string(c.width),
                     "height=" + std::to_string(c.height),
                     "wall_distance_m=" + ReprValue(c.wall_distance_m)});
      });
  m.def(
      "load_calibration",
      [](const std::filesystem::path& p) {
        return std::make_shared<OffsetCalibration>(LoadCalibration(p));
      },
      py::arg("path"), "Reads and validates a calibration file.");
  m.def("save_calibration", &SaveCalibration, py::arg("path"), py::arg("calibration"),
        "Writes a calibration file atomically.");
  m.def(
      "calibrate",
      [](Camera& camera, double wall_distance_m, int frames,
         std::function<void(const std::string&, int, int, const std::string&)> progress,
         const py::kwargs& kwargs) {
        WallCalibrationOptions o;
        o.wall_distance_m = wall_distance_m;
        o.frames = frames;
        for (const auto& [k, v] : kwargs) {
          const std::string key = py::str(k);
          // pybind's own cast error names neither the option nor the type it wants.
          const auto as_int = [&key](py::handle value) {
            if (!py::isinstance<py::int_>(value) || py::isinstance<py::bool_>(value)) {
              throw py::type_error("calibrate() option '" + key + "' must be an int");
            }
            return value.cast<int>();
          };
          if (key == "warmup_max_frames") {
            o.warmup_max_frames = as_int(v);
          } else if (key == "warmup_window_frames") {
            o.warmup_window_frames = as_int(v);
          } else if (key == "controller_max_frames") {
            o.controller_max_frames = as_int(v);
          } else if (key == "min_valid_fraction") {
            if (!py::isinstance<py::float_>(v) && !py::isinstance<py::int_>(v)) {
              throw py::type_error("calibrate() option '" + key + "' must be a number");
            }
            o.min_valid_fraction = v.cast<double>();
          } else {
            throw py::type_error("calibrate() has no option '" + key + "'");
          }
        }
        o.Validate();
        ProgressCallback callback;
        if (progress) {
          callback = [&progress](const CalibrationProgress& p) {
            py::gil_scoped_acquire acquire;
            progress(std::string(p.phase), p.frame, p.total, p.message);
          };
        }
        WallCalibrationReport report;
        OffsetCalibration calibration;
        {
          py::gil_scoped_release release;
          calibration = CalibrateOffsets(camera, o, callback, &report);
        }
        return std::make_shared<OffsetCalibration>(std::move(calibration));
      },
      py::arg("camera"), py::arg("wall_distance_m"), py::arg("frames") = 50,
      py::arg("progress") = nullptr,
      "The paper's per-pixel calibration: the camera faces a white wall at `wall_distance_m` "
      "(perpendicular, m); warms up, sets the exposure, averages `frames` frames and returns "
      "the offset matrix. progress(phase, frame, total, message) is called as it goes. Options: "
      "warmup_max_frames, warmup_window_frames, controller_max_frames, min_valid_fraction.");
}

void BindWriters(py::module_& m) {
  m.def(
      "write_ply",
      [](const std::filesystem::path& path, const PointCloud& cloud, bool ascii, bool only_valid) {
        WritePly(path, cloud, ascii ? PlyFormat::kAscii : PlyFormat::kBinary, only_valid);
      },
      py::arg("path"), py::arg("cloud"), py::arg("ascii") = false, py::arg("only_valid") = false,
      "Writes a PointCloud as PLY (atomically).");
  m.def(
      "write_pcd",
      [](const std::filesystem::path& path, const PointCloud& cloud, bool only_valid) {
        WritePcd(path, cloud, only_valid);
      },
      py::arg("path"), py::arg("cloud"), py::arg("only_valid") = false,
      "Writes a PointCloud as PCD (atomically).");
  m.def(
      "write_png",
      [](const std::filesystem::path& path, py::object image) {
        py::array a = py::reinterpret_borrow<py::array>(image);
        if (py::isinstance<py::array>(image) && a.ndim() == 2) {
          WritePngGray16(path, ToImage<std::uint16_t>(image, "image"));
        } else {
          WritePngRgb8(path, ToImage<Rgb8>(image, "image"));
        }
      },
      py::arg("path"), py::arg("image"),
      "Writes a uint8 (H, W, 3) colour image or a uint16 (H, W) grey image as PNG.");
}

}  // namespace

void BindIo(py::module_& m) {
  BindRecordings(m);
  BindCalibration(m);
  BindWriters(m);
}

}  // namespace tofcam::python

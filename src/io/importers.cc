#include "tofcam/io/importers.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <system_error>

#include "import_util.h"
#include "tofcam/accuracy/delta_l.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam {

using io_internal::BlankFrame;
using io_internal::CheckImageSize;
using io_internal::FrequencyForRange;
using io_internal::ImportedCameraInfo;
using io_internal::SetAmplitude;
using io_internal::SetDistanceMm;

namespace {

[[noreturn]] void FormatError(const std::string& name, const std::string& what) {
  throw Error(ErrorCode::kFormat, name + ": " + what);
}

std::uint16_t U16Le(const std::string_view bytes, std::size_t offset) {
  return static_cast<std::uint16_t>(static_cast<unsigned char>(bytes[offset]) |
                                    (static_cast<unsigned char>(bytes[offset + 1]) << 8));
}

// ADTF3175 in 512 x 512 (binned) mode: 75 deg x 75 deg field of view (data sheet); no calibration
// ships with the sample files, so the principal point is the image centre.
CameraIntrinsics AdiNominalIntrinsics(int width, int height) {
  CameraIntrinsics k;
  k.width = width;
  k.height = height;
  const double half_fov = 37.5 * kPi / 180.0;
  k.fx_px = 0.5 * width / std::tan(half_fov);
  k.fy_px = 0.5 * height / std::tan(half_fov);
  k.cx_px = 0.5 * (width - 1);
  k.cy_px = 0.5 * (height - 1);
  return k;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// ADI ADTF3175

ImportedSequence ParseAdiInterleaved(std::string_view bytes, int width, int height,
                                     const std::string& name) {
  CheckImageSize(width, height, name);
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (bytes.size() != n * 5) {
    FormatError(name, std::to_string(bytes.size()) + " bytes, expected " + std::to_string(n * 5) +
                          " (" + std::to_string(width) + " x " + std::to_string(height) +
                          " x 5 interleaved)");
  }
  ImportedSequence seq;
  const double f = FrequencyForRange(kImportRangeAdiM);
  seq.camera = ImportedCameraInfo("ADI ADTF3175", AdiNominalIntrinsics(width, height), f);
  Frame frame = BlankFrame(width, height, seq.camera.model, f);
  frame.confidence = Image<float>(width, height);
  frame.info.confidence_source = "ADI 255 - confidence byte (0 = best in the file)";
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t o = i * 5;
    SetDistanceMm(frame, i, U16Le(bytes, o), kImportRangeAdiM);
    // Byte o + 2 is the camera's confidence, 0 = best: kept, turned so that higher is better
    // (Frame::confidence). The camera already zeroes the depth of pixels it distrusts.
    frame.confidence[i] = static_cast<float>(255 - static_cast<unsigned char>(bytes[o + 2]));
    SetAmplitude(frame, i, U16Le(bytes, o + 3));
  }
  seq.frames.push_back(std::move(frame));
  return seq;
}

ImportedSequence ImportAdiInterleaved(const std::filesystem::path& bin_file, int width,
                                      int height) {
  CheckImageSize(width, height, bin_file.string());
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  const std::string bytes = io_internal::ReadExactly(
      bin_file, n * 5,
      "ADI interleaved " + std::to_string(width) + " x " + std::to_string(height) + " x 5");
  return ParseAdiInterleaved(bytes, width, height, bin_file.string());
}

ImportedSequence ImportAdiRaw(const std::filesystem::path& depth_file,
                              const std::filesystem::path& ir_file, int width, int height) {
  CheckImageSize(width, height, depth_file.string());
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  const std::string what = "uint16 " + std::to_string(width) + " x " + std::to_string(height);
  const std::string depth = io_internal::ReadExactly(depth_file, n * 2, what);
  const std::string ir = io_internal::ReadExactly(ir_file, n * 2, what);
  ImportedSequence seq;
  const double f = FrequencyForRange(kImportRangeAdiM);
  seq.camera = ImportedCameraInfo("ADI ADTF3175", AdiNominalIntrinsics(width, height), f);
  Frame frame = BlankFrame(width, height, seq.camera.model, f);
  for (std::size_t i = 0; i < n; ++i) {
    SetDistanceMm(frame, i, U16Le(depth, 2 * i), kImportRangeAdiM);
    SetAmplitude(frame, i, U16Le(ir, 2 * i));
  }
  seq.frames.push_back(std::move(frame));
  return seq;
}

// ---------------------------------------------------------------------------------------------
// Azure Kinect

CameraIntrinsics ParseAzureKinectCalibration(std::string_view json, int width, int height,
                                             const std::string& name) {
  CheckImageSize(width, height, name);
  // Depth modes of the Azure Kinect SDK: calibration resolution and crop of each output size.
  struct Mode {
    int width, height, calibration_resolution, crop_x, crop_y;
  };
  static constexpr Mode kModes[] = {{640, 576, 1024, 192, 180},
                                    {320, 288, 512, 96, 90},
                                    {512, 512, 512, 0, 0},
                                    {1024, 1024, 1024, 0, 0}};
  const Mode* mode = nullptr;
  for (const Mode& m : kModes) {
    if (m.width == width && m.height == height) mode = &m;
  }
  if (mode == nullptr) {
    throw Error(ErrorCode::kUnsupported, name + ": no Azure Kinect depth mode has " +
                                             std::to_string(width) + " x " +
                                             std::to_string(height) + " pixels");
  }
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(json.begin(), json.end());
  } catch (const nlohmann::json::exception& e) {
    FormatError(name, std::string("invalid JSON: ") + e.what());
  }
  try {
    const auto& cameras = doc.at("CalibrationInformation").at("Cameras");
    if (!cameras.is_array()) FormatError(name, "'Cameras' is not an array");
    for (const auto& cam : cameras) {
      if (!cam.is_object() || cam.value("Purpose", "") != "CALIBRATION_CameraPurposeDepth") {
        continue;
      }
      const auto& intr = cam.at("Intrinsics");
      const std::string model = intr.at("ModelType").get<std::string>();
      if (model.find("BrownConrady") == std::string::npos) {
        throw Error(ErrorCode::kUnsupported,
                    name + ": lens model '" + model + "' (only Brown-Conrady is supported)");
      }
      const auto& p = intr.at("ModelParameters");
      if (!p.is_array() || p.size() < 14) {
        FormatError(name, "depth camera ModelParameters must have 14 numbers");
      }
      double v[14];
      for (int i = 0; i < 14; ++i) {
        if (!p[i].is_number()) FormatError(name, "ModelParameters[" + std::to_string(i) + "]");
        v[i] = p[i].get<double>();
        if (!std::isfinite(v[i])) FormatError(name, "ModelParameters has a non-finite value");
      }
      const int sw = cam.at("SensorWidth").get<int>();
      const int sh = cam.at("SensorHeight").get<int>();
      if (sw != 1024 || sh != 1024) {
        FormatError(name, "depth sensor is " + std::to_string(sw) + " x " + std::to_string(sh) +
                              ", expected 1024 x 1024");
      }
      if (v[10] != 0.0 || v[11] != 0.0) {
        throw Error(ErrorCode::kUnsupported,
                    name + ": a distortion centre (codx, cody) other than 0 is not supported");
      }
      // Parameters are normalised by the calibration resolution; the SDK converts them to the
      // mode's pixels by scaling, subtracting the crop, and shifting by half a pixel because its
      // normalised coordinates put pixel corners (not centres) at integers.
      const double r = mode->calibration_resolution;
      CameraIntrinsics k;
      k.width = width;
      k.height = height;
      k.cx_px = v[0] * r - mode->crop_x - 0.5;
      k.cy_px = v[1] * r - mode->crop_y - 0.5;
      k.fx_px = v[2] * r;
      k.fy_px = v[3] * r;
      k.k1 = v[4], k.k2 = v[5], k.k3 = v[6], k.k4 = v[7], k.k5 = v[8], k.k6 = v[9];
      k.p2 = v[12];
      k.p1 = v[13];
      try {
        k.Validate();
      } catch (const Error& e) {
        FormatError(name, std::string("depth intrinsics invalid: ") + e.what());
      }
      return k;
    }
  } catch (const nlohmann::json::exception& e) {
    FormatError(name, std::string("unexpected calibration layout: ") + e.what());
  }
  FormatError(name, "no camera with Purpose CALIBRATION_CameraPurposeDepth");
}

ImportedSequence ImportAzureKinect(const std::filesystem::path& depth_file,
                                   const std::filesystem::path& ir_file,
                                   const std::filesystem::path& calibration_json, int width,
                                   int height) {
  CheckImageSize(width, height, depth_file.string());
  const std::string json = ReadFile(calibration_json, std::size_t{1} << 20);
  const CameraIntrinsics k =
      ParseAzureKinectCalibration(json, width, height, calibration_json.string());
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  const std::string what = "uint16 " + std::to_string(width) + " x " + std::to_string(height);
  const std::string depth = io_internal::ReadExactly(depth_file, n * 2, what);
  const std::string ir = io_internal::ReadExactly(ir_file, n * 2, what);
  ImportedSequence seq;
  const double f = FrequencyForRange(kImportRangeAzureKinectM);
  seq.camera = ImportedCameraInfo("Azure Kinect", k, f);
  Frame frame = BlankFrame(width, height, seq.camera.model, f);
  const RayTable rays = MakeRayTable(k);
  for (std::size_t i = 0; i < n; ++i) {
    const double z_mm = U16Le(depth, 2 * i);
    // Azure Kinect depth is z along the optical axis; tofcam registers hold radial distance.
    const double ray_z = rays.z[i];
    SetDistanceMm(frame, i, ray_z > 0 ? z_mm / ray_z : 0.0, kImportRangeAzureKinectM);
    const std::uint16_t ir_value = U16Le(ir, 2 * i);
    SetAmplitude(frame, i, ir_value);  // 65535 (sensor saturation) > 65532 -> kSaturated
  }
  seq.frames.push_back(std::move(frame));
  return seq;
}

// ---------------------------------------------------------------------------------------------
// MESA SwissRanger .dat

namespace {

struct Line {
  std::string_view text;
  std::size_t number;  // 1-based
};

std::vector<Line> SplitLines(std::string_view text) {
  std::vector<Line> lines;
  std::size_t pos = 0, number = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    ++number;
    // Trim spaces and '\r'.
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t')) {
      line.remove_suffix(1);
    }
    while (!line.empty() && (line.front() == ' ' || line.front() == '\t')) line.remove_prefix(1);
    if (!line.empty()) lines.push_back({line, number});
    pos = end + 1;
  }
  return lines;
}

// Parses whitespace-separated numbers; false on a token that is not a number.
bool ParseNumbers(std::string_view line, std::vector<double>& out) {
  out.clear();
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() &&
           (line[i] == ' ' || line[i] == '\t' || line[i] == ',' || line[i] == ';')) {
      ++i;
    }
    if (i >= line.size()) break;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != ',' &&
           line[j] != ';') {
      ++j;
    }
    std::string_view token = line.substr(i, j - i);
    if (!token.empty() && token.front() == '+') token.remove_prefix(1);
    double v = 0;
    const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), v);
    if (ec != std::errc() || ptr != token.data() + token.size()) return false;
    out.push_back(v);
    i = j;
  }
  return true;
}

// SR-4000: 176 x 144 px, 40 µm pitch, 10 mm lens (MESA data sheet).
CameraIntrinsics MesaNominalIntrinsics(int width, int height) {
  CameraIntrinsics k;
  k.width = width;
  k.height = height;
  k.fx_px = k.fy_px = 250.0;
  k.cx_px = 0.5 * (width - 1);
  k.cy_px = 0.5 * (height - 1);
  return k;
}

}  // namespace

namespace {

// The sections of a MESA sample-viewer export, recognised by words in their '%' header lines.
enum class MesaSection { kZ, kX, kY, kAmplitude, kConfidence, kTimestamp, kOther };
constexpr int kMesaImageSections = 5;

MesaSection ClassifyMesaHeader(std::string_view header) {
  // Lower-case words of the header; units in brackets and punctuation separate words.
  std::vector<std::string> words(1);
  for (char c : header) {
    if (std::isalnum(static_cast<unsigned char>(c))) {
      words.back() += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    } else if (!words.back().empty()) {
      words.emplace_back();
    }
  }
  auto word = [&](const char* w) {
    return std::find(words.begin(), words.end(), w) != words.end();
  };
  auto part = [&](const char* w) {
    return std::any_of(words.begin(), words.end(),
                       [&](const std::string& x) { return x.find(w) != std::string::npos; });
  };
  if (part("time")) return MesaSection::kTimestamp;
  if (part("xvector") || word("x")) return MesaSection::kX;
  if (part("yvector") || word("y")) return MesaSection::kY;
  if (part("distance") || part("zvector") || word("z")) return MesaSection::kZ;
  if (part("amplitude")) return MesaSection::kAmplitude;
  if (part("confidence")) return MesaSection::kConfidence;
  return MesaSection::kOther;
}

const char* MesaSectionName(int s) {
  static constexpr const char* kNames[] = {"Calibrated Distance", "Calibrated xVector",
                                           "Calibrated yVector", "Amplitude", "Confidence map"};
  return kNames[s];
}

struct MesaRawFrame {
  std::vector<double> channel[kMesaImageSections];
  std::optional<double> timestamp_ms;
  std::size_t first_line = 0;
};

}  // namespace

namespace {

// Parses one export. Time stamps are made relative to `t0_ms`, which is set from the first
// frame when empty (a sequence of files shares the first file's). `camera` (when not null) is
// the sequence's camera: its size must match and its intrinsics are kept.
ImportedSequence ParseMesaDatImpl(std::string_view text, const std::string& name,
                                  std::optional<double>& t0_ms, const CameraInfo* camera) {
  constexpr int kMaxSide = 4096;
  constexpr std::size_t kMaxFrames = 100000;
  const std::vector<Line> lines = SplitLines(text);
  auto where = [&](std::size_t index) {
    return name + " line " +
           std::to_string(index < lines.size() ? lines[index].number
                                               : (lines.empty() ? 0 : lines.back().number));
  };
  int width = 0, height = 0;
  std::vector<double> numbers;
  std::vector<MesaRawFrame> raw;
  MesaRawFrame current;
  bool open = false;  // `current` has at least one section
  auto finish = [&](std::size_t at) {
    if (!open) return;
    for (int s : {0, 1, 2, 3}) {
      if (current.channel[s].empty()) {
        throw Error(ErrorCode::kFormat, where(at) + ": frame " + std::to_string(raw.size() + 1) +
                                            " has no '% " + MesaSectionName(s) + "' section");
      }
    }
    if (!current.timestamp_ms) {
      throw Error(ErrorCode::kFormat, where(at) + ": frame " + std::to_string(raw.size() + 1) +
                                          " has no timestamp section ('% ... time stamp [ms]')");
    }
    if (raw.size() >= kMaxFrames) FormatError(name, "more than 100000 frames");
    raw.push_back(std::move(current));
    current = MesaRawFrame();
    open = false;
  };
  std::size_t li = 0;
  while (li < lines.size()) {
    if (lines[li].text.front() != '%') {
      throw Error(ErrorCode::kFormat, where(li) + ": numbers outside a '%' section");
    }
    std::string_view header = lines[li].text.substr(1);
    const MesaSection kind = ClassifyMesaHeader(header);
    const std::size_t header_line = li;
    ++li;
    // The rows of this section: every line up to the next '%' line.
    const std::size_t rows_begin = li;
    while (li < lines.size() && lines[li].text.front() != '%') ++li;
    const std::size_t rows = li - rows_begin;
    if (kind == MesaSection::kOther) continue;  // a comment or a section tofcam does not use
    if (kind == MesaSection::kTimestamp) {
      // "% ... time stamp [ms]" then a row whose first finite number is the time stamp (the
      // sample viewer pads the row with nan to the image width); an older layout puts the
      // number on the header line itself ("% timestamp [ms]: 1234").
      double ts = std::numeric_limits<double>::quiet_NaN();
      if (rows == 0) {
        const std::size_t sep = header.find_last_of(":=");
        if (sep != std::string_view::npos && ParseNumbers(header.substr(sep + 1), numbers) &&
            !numbers.empty()) {
          ts = numbers.front();
        }
      } else {
        if (rows > 1) {
          throw Error(ErrorCode::kFormat,
                      where(rows_begin + 1) + ": time stamp section has more than one row");
        }
        if (!ParseNumbers(lines[rows_begin].text, numbers)) {
          throw Error(ErrorCode::kFormat, where(rows_begin) + ": not a list of numbers");
        }
        for (double v : numbers) {
          if (std::isfinite(v)) {
            ts = v;
            break;
          }
        }
      }
      if (!std::isfinite(ts)) {
        throw Error(ErrorCode::kFormat, where(rows == 0 ? header_line : rows_begin) +
                                            ": expected a time stamp (ms), found none");
      }
      if (!open) {
        throw Error(ErrorCode::kFormat, where(header_line) + ": time stamp before any image");
      }
      current.timestamp_ms = ts;
      finish(li);
      continue;
    }
    const int s = static_cast<int>(kind);
    if (open && !current.channel[s].empty()) finish(header_line);  // a new frame starts
    if (!open) current.first_line = header_line;
    open = true;
    if (height == 0) {
      if (rows == 0) throw Error(ErrorCode::kFormat, where(header_line) + ": empty section");
      if (rows > static_cast<std::size_t>(kMaxSide)) {
        throw Error(ErrorCode::kFormat, where(header_line) + ": more than 4096 rows in a section");
      }
      height = static_cast<int>(rows);
    }
    if (rows != static_cast<std::size_t>(height)) {
      throw Error(ErrorCode::kFormat, where(header_line) + ": section '" + std::string(header) +
                                          "' has " + std::to_string(rows) + " rows, expected " +
                                          std::to_string(height));
    }
    std::vector<double>& values = current.channel[s];
    for (std::size_t r = rows_begin; r < li; ++r) {
      if (!ParseNumbers(lines[r].text, numbers)) {
        throw Error(ErrorCode::kFormat, where(r) + ": not a list of numbers");
      }
      if (width == 0) {
        if (numbers.empty() || numbers.size() > static_cast<std::size_t>(kMaxSide)) {
          throw Error(ErrorCode::kFormat,
                      where(r) + ": row of " + std::to_string(numbers.size()) + " values");
        }
        width = static_cast<int>(numbers.size());
      }
      if (numbers.size() != static_cast<std::size_t>(width)) {
        throw Error(ErrorCode::kFormat, where(r) + ": row has " + std::to_string(numbers.size()) +
                                            " values, expected " + std::to_string(width));
      }
      values.insert(values.end(), numbers.begin(), numbers.end());
    }
  }
  finish(lines.size());
  if (raw.empty()) FormatError(name, "no frames (no '% Calibrated Distance' section)");

  ImportedSequence seq;
  const double f = kMesaModulationFrequencyHz;
  const double range_m = UnambiguousRangeM(f);
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  auto usable = [](const MesaRawFrame& r, std::size_t i) {
    const bool confident = r.channel[4].empty() || r.channel[4][i] > 0;
    return r.channel[0][i] > 0 && std::isfinite(r.channel[0][i]) &&
           std::isfinite(r.channel[1][i]) && std::isfinite(r.channel[2][i]) && confident;
  };
  if (camera != nullptr) {
    if (camera->width() != width || camera->height() != height) {
      FormatError(name, std::to_string(width) + " x " + std::to_string(height) +
                            " pixels, the sequence's first file has " +
                            std::to_string(camera->width()) + " x " +
                            std::to_string(camera->height()));
    }
    seq.camera = *camera;
  } else {
    std::vector<io_internal::PixelPoint> points;
    for (std::size_t i = 0; i < n; ++i) {
      const MesaRawFrame& r = raw.front();
      if (usable(r, i)) {
        points.push_back({static_cast<double>(i % width), static_cast<double>(i / width),
                          r.channel[1][i], r.channel[2][i], r.channel[0][i]});
      }
    }
    seq.camera = ImportedCameraInfo(
        "MESA SR-4000",
        io_internal::FitPinhole(points, width, height, MesaNominalIntrinsics(width, height)), f);
  }
  if (!t0_ms) t0_ms = *raw.front().timestamp_ms;
  const double t0 = *t0_ms;
  for (std::size_t fi = 0; fi < raw.size(); ++fi) {
    const MesaRawFrame& r = raw[fi];
    Frame frame = BlankFrame(width, height, seq.camera.model, f);
    frame.info.sequence = fi;
    const double dt_ns = (*r.timestamp_ms - t0) * 1e6;
    if (!(std::abs(dt_ns) < 9e18)) FormatError(name, "time stamp out of range");
    frame.info.timestamp_ns = static_cast<std::int64_t>(std::llround(dt_ns));
    const bool has_confidence = !r.channel[4].empty();
    if (has_confidence) {
      frame.confidence = Image<float>(width, height);
      frame.info.confidence_source = "MESA confidence map";
    }
    for (std::size_t i = 0; i < n; ++i) {
      const double z = r.channel[0][i], x = r.channel[1][i], y = r.channel[2][i];
      const double radial_mm = 1000.0 * std::sqrt(x * x + y * y + z * z);
      SetDistanceMm(frame, i, usable(r, i) ? radial_mm : 0.0, range_m);
      SetAmplitude(frame, i, r.channel[3][i]);
      if (has_confidence) {
        const double c = r.channel[4][i];
        frame.confidence[i] =
            std::isfinite(c) && c > 0 ? static_cast<float>(std::min(c, 1e9)) : 0.0f;
      }
    }
    seq.frames.push_back(std::move(frame));
  }
  return seq;
}

}  // namespace

ImportedSequence ParseMesaDat(std::string_view text, const std::string& name) {
  std::optional<double> t0_ms;
  return ParseMesaDatImpl(text, name, t0_ms, nullptr);
}

namespace {

// "frm_2.dat" before "frm_10.dat": digit runs compare by value.
bool NaturalLess(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (std::isdigit(static_cast<unsigned char>(a[i])) &&
        std::isdigit(static_cast<unsigned char>(b[j]))) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      std::string_view da(a.data() + i, ie - i), db(b.data() + j, je - j);
      while (da.size() > 1 && da.front() == '0') da.remove_prefix(1);
      while (db.size() > 1 && db.front() == '0') db.remove_prefix(1);
      if (da.size() != db.size()) return da.size() < db.size();
      if (da != db) return da < db;
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

// Shell-style match of '*' and '?' (no character classes).
bool GlobMatch(std::string_view pattern, std::string_view s) {
  std::size_t p = 0, i = 0, star = std::string_view::npos, mark = 0;
  while (i < s.size()) {
    if (p < pattern.size() && (pattern[p] == '?' || pattern[p] == s[i])) {
      ++p;
      ++i;
    } else if (p < pattern.size() && pattern[p] == '*') {
      star = p++;
      mark = i;
    } else if (star != std::string_view::npos) {
      p = star + 1;
      i = ++mark;
    } else {
      return false;
    }
  }
  while (p < pattern.size() && pattern[p] == '*') ++p;
  return p == pattern.size();
}

}  // namespace

std::vector<std::filesystem::path> ExpandSequencePath(const std::filesystem::path& path,
                                                      const std::string& extension) {
  namespace fs = std::filesystem;
  const std::string text = path.string();
  std::vector<fs::path> files;
  std::error_code ec;
  if (text.find_first_of("*?") != std::string::npos) {
    const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
    const std::string pattern = path.filename().string();
    if (dir.string().find_first_of("*?") != std::string::npos) {
      throw Error(ErrorCode::kInvalidArgument,
                  text + ": wildcards are allowed in the file name only, not in folders");
    }
    if (!fs::is_directory(dir, ec))
      throw Error(ErrorCode::kNotFound, text + ": no folder " + dir.string());
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      if (entry.is_regular_file(ec) && GlobMatch(pattern, entry.path().filename().string())) {
        files.push_back(entry.path());
      }
    }
    if (files.empty()) throw Error(ErrorCode::kNotFound, text + ": no file matches");
  } else if (fs::is_directory(path, ec)) {
    for (const auto& entry : fs::directory_iterator(path, ec)) {
      if (entry.is_regular_file(ec) && entry.path().extension() == extension) {
        files.push_back(entry.path());
      }
    }
    if (files.empty()) {
      throw Error(ErrorCode::kNotFound, text + ": folder holds no " + extension + " file");
    }
  } else {
    if (!fs::exists(path, ec)) throw Error(ErrorCode::kNotFound, text + ": no such file");
    files.push_back(path);
  }
  std::sort(files.begin(), files.end(), [](const fs::path& a, const fs::path& b) {
    return NaturalLess(a.filename().string(), b.filename().string());
  });
  return files;
}

ImportedSequence ImportMesaDat(const std::filesystem::path& path) {
  const std::vector<std::filesystem::path> files = ExpandSequencePath(path, ".dat");
  ImportedSequence seq;
  std::optional<double> t0_ms;
  for (std::size_t k = 0; k < files.size(); ++k) {
    // The parsed values take about 20 times the text's size in memory: cap a file at 256 MiB.
    ImportedSequence part =
        ParseMesaDatImpl(ReadFile(files[k], std::size_t{1} << 28), files[k].string(), t0_ms,
                         k == 0 ? nullptr : &seq.camera);
    if (k == 0) seq.camera = part.camera;  // intrinsics fitted on the first file's first frame
    for (Frame& frame : part.frames) {
      frame.info.sequence = seq.frames.size();
      seq.frames.push_back(std::move(frame));
    }
  }
  return seq;
}

// ---------------------------------------------------------------------------------------------
// Dispatch

std::vector<std::string> ImportFormats() {
  return {"adi-interleaved", "adi-raw", "azure-kinect", "ifm-o3d3xx", "mesa-dat"};
}

namespace {
std::vector<std::string> SplitComma(const std::string& s) {
  std::vector<std::string> parts;
  std::size_t pos = 0;
  while (true) {
    const std::size_t c = s.find(',', pos);
    parts.push_back(s.substr(pos, c == std::string::npos ? std::string::npos : c - pos));
    if (c == std::string::npos) break;
    pos = c + 1;
  }
  return parts;
}
}  // namespace

ImportedSequence ImportFromSpec(const std::string& spec) {
  const std::size_t colon = spec.find(':');
  const std::string format = spec.substr(0, colon);
  const std::string rest = colon == std::string::npos ? "" : spec.substr(colon + 1);
  auto bad = [&](const std::string& why) -> Error {
    return Error(ErrorCode::kInvalidArgument, "import spec '" + spec + "': " + why);
  };
  if (colon == std::string::npos || rest.empty()) throw bad("expected <format>:<path>");
  const auto parts = SplitComma(rest);
  if (format == "ifm-o3d3xx") return ImportIfmO3d3xx(rest);
  if (format == "adi-interleaved") return ImportAdiInterleaved(rest);
  if (format == "mesa-dat") return ImportMesaDat(rest);
  if (format == "adi-raw") {
    if (parts.size() == 2) return ImportAdiRaw(parts[0], parts[1]);
    if (parts.size() != 1) throw bad("expected <depth.bin>[,<ir.bin>]");
    const std::filesystem::path depth = parts[0];
    std::string ir_name = depth.filename().string();
    const std::size_t at = ir_name.rfind("depth");
    if (at == std::string::npos) throw bad("cannot derive the IR file name; give <depth>,<ir>");
    ir_name.replace(at, 5, "ir");
    return ImportAdiRaw(depth, depth.parent_path() / ir_name);
  }
  if (format == "azure-kinect") {
    // The depth mode follows from the image size (ImportAzureKinect): from the depth file's
    // size, or from which depth_<W>x<H>_u16le.bin a directory holds.
    constexpr int kModes[4][2] = {{640, 576}, {320, 288}, {512, 512}, {1024, 1024}};
    if (parts.size() == 3) {
      std::error_code ec;
      const auto bytes = std::filesystem::file_size(parts[0], ec);
      for (const auto& m : kModes) {
        if (!ec && bytes == 2ull * static_cast<unsigned>(m[0]) * static_cast<unsigned>(m[1])) {
          return ImportAzureKinect(parts[0], parts[1], parts[2], m[0], m[1]);
        }
      }
      if (ec) return ImportAzureKinect(parts[0], parts[1], parts[2]);  // names the missing file
      throw Error(ErrorCode::kFormat,
                  parts[0] + ": " + std::to_string(bytes) +
                      " bytes is no Azure Kinect depth mode (uint16 640x576, 320x288, 512x512 "
                      "or 1024x1024)");
    }
    if (parts.size() != 1) throw bad("expected <dir> or <depth.bin>,<ir.bin>,<calibration.json>");
    const std::filesystem::path dir = parts[0];
    for (const auto& m : kModes) {
      const std::string size = std::to_string(m[0]) + "x" + std::to_string(m[1]);
      const std::filesystem::path depth = dir / ("depth_" + size + "_u16le.bin");
      if (std::filesystem::exists(depth)) {
        return ImportAzureKinect(depth, dir / ("ir_" + size + "_u16le.bin"),
                                 dir / "calibration.json", m[0], m[1]);
      }
    }
    return ImportAzureKinect(dir / "depth_640x576_u16le.bin", dir / "ir_640x576_u16le.bin",
                             dir / "calibration.json");  // names the missing file
  }
  std::string known;
  for (const auto& f : ImportFormats()) known += (known.empty() ? "" : ", ") + f;
  throw bad("unknown format '" + format + "' (known: " + known + ")");
}

// ---------------------------------------------------------------------------------------------
// ImportedCamera

std::optional<double> SelfCalibratedNoiseScale(const std::vector<Frame>& frames) {
  if (frames.size() < 3) return std::nullopt;
  // The metric copies and their ΔL images (about 22 bytes a pixel) of every frame would triple
  // what the importer already holds: the first frames up to 2^22 pixels in all (at least
  // three) are plenty for σ per pixel.
  constexpr std::size_t kMaxPixels = std::size_t{1} << 22;
  const std::size_t per_frame = std::max<std::size_t>(frames.front().distance.size(), 1);
  const std::size_t used =
      std::min(frames.size(), std::max<std::size_t>(3, kMaxPixels / per_frame));
  std::vector<MetricFrame> metric;
  metric.reserve(used);
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const Frame& f = frames[k];
    if (f.width() != frames.front().width() || f.height() != frames.front().height()) {
      return std::nullopt;
    }
    if (k < used) metric.push_back(ConvertToMetric(f));
  }
  try {
    // No gate on R²: σ from 3 frames has a relative error of ~70 % per pixel, so R² is near 0
    // even for a perfect model. A scene that moved inflates σ, hence the scale: the accuracy
    // filter then rejects more, which fails safe. The fit's cut is relative to L, so the
    // importer's register convention (ifm: L = 32.8 m) needs nothing special.
    const DeltaLFitOptions options;
    const DeltaLScaleFit fit = FitDeltaLScale(metric, options);
    if (!(fit.scale > 0.0) || !std::isfinite(fit.scale)) return std::nullopt;
    return fit.scale;
  } catch (const Error&) {
    return std::nullopt;  // too few pixels usable in every frame
  }
}

ImportedCamera::ImportedCamera(ImportedSequence sequence, bool loop)
    : sequence_(std::move(sequence)), loop_(loop) {
  if (sequence_.frames.empty()) {
    throw Error(ErrorCode::kFormat, "imported " + sequence_.camera.model + " sequence is empty");
  }
}

const FrameInfo& ImportedCamera::NextInfo() const {
  return sequence_.frames[std::min(next_, sequence_.frames.size() - 1)].info;
}

std::optional<Frame> ImportedCamera::Grab() {
  if (next_ >= sequence_.frames.size()) {
    if (!loop_) return std::nullopt;
    next_ = 0;
    continuation_.Wrap(sequence_.frames.front().info, sequence_.frames.back().info,
                       sequence_.frames.size());
  }
  Frame frame = sequence_.frames[next_++];
  continuation_.Apply(frame.info);
  return frame;
}

namespace {
[[noreturn]] void ImportUnsupported(const std::string& model, const std::string& what) {
  throw Error(ErrorCode::kUnsupported,
              "imported " + model + " data cannot change " + what + " (only the recorded value)");
}
}  // namespace

void ImportedCamera::SetIntegrationTimeRegister(int reg) {
  if (reg != IntegrationTimeRegister()) {
    ImportUnsupported(sequence_.camera.model, "the integration time to " + std::to_string(reg));
  }
}
int ImportedCamera::IntegrationTimeRegister() const { return NextInfo().integration_time_register; }
void ImportedCamera::SetModulationFrequencyHz(double hz) {
  if (hz != sequence_.camera.modulation_frequency_hz) {
    ImportUnsupported(sequence_.camera.model, "the modulation frequency");
  }
}
void ImportedCamera::SetDistanceOffsetRegister(int reg) {
  if (reg != DistanceOffsetRegister()) {
    ImportUnsupported(sequence_.camera.model, "the distance offset");
  }
}
int ImportedCamera::DistanceOffsetRegister() const { return NextInfo().distance_offset_register; }
void ImportedCamera::SetPanAngleRad(double angle_rad) {
  if (angle_rad != PanAngleRad()) ImportUnsupported(sequence_.camera.model, "the pan angle");
}
double ImportedCamera::PanAngleRad() const { return NextInfo().pan_angle_rad; }

}  // namespace tofcam

#include "viewer_server.h"

#include <httplib.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <ctime>
#include <deque>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

#include "tofcam/color/false_color.h"
#include "tofcam/core/error.h"
#include "tofcam/io/cloud_io.h"
#include "tofcam/io/recording.h"
#include "web_assets.h"

namespace tofcam::viewer {
namespace {

using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

constexpr std::uint32_t kMagic = 0x56464f54;  // "TOFV" little-endian
constexpr std::uint32_t kFormatVersion = 1;

std::string ReadWholeFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

double CpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

json Finite(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

// What the page may change; the HTTP threads validate into a copy and commit it whole, the loop
// applies it before its next frame.
struct Desired {
  PipelineOptions pipeline;
  std::uint64_t pipeline_version = 0;
  bool paused = false;
  int step = 0;  // frames to run while paused
  std::optional<double> pan_rad;
  int record = 0;                  // +1 start, -1 stop
  std::unique_ptr<Camera> camera;  // a reopened source (new scene parameters)
  std::string camera_spec;
};

// Most frames a paused camera may have queued to step through.
constexpr int kMaxSteps = 1000;

// One request's controls applied to a copy of Desired (ViewerServer::Impl::Stage).
struct Staged {
  PipelineOptions pipeline;
  bool paused = false;
  int step = 0;
  std::optional<double> pan;
  int record = 0;
  std::string spec;
  bool reopen = false;   // the source is to be reopened with `spec`
  bool changed = false;  // a pipeline key: rebuild the pipeline
};

// Type-checked readers for one control value; they throw std::string (the 400 reason).
double Number(const json& v, const std::string& key, double lo, double hi, bool lo_open = false) {
  if (!v.is_number()) throw std::string("control '" + key + "' must be a number");
  const double x = v.get<double>();
  if (!std::isfinite(x) || (lo_open ? !(x > lo) : !(x >= lo)) || !(x <= hi)) {
    std::ostringstream msg;
    msg << "control '" << key << "' = " << x << " is outside " << (lo_open ? "(" : "[") << lo
        << ", " << hi << "]";
    throw msg.str();
  }
  return x;
}

int Integer(const json& v, const std::string& key, int lo, int hi) {
  if (!v.is_number_integer()) throw std::string("control '" + key + "' must be an integer");
  if (v.is_number_unsigned() && v.get<unsigned long long>() > static_cast<unsigned>(hi)) {
    // Above 2^63 a signed read would wrap to a negative number in the message.
    throw "control '" + key + "' = " + std::to_string(v.get<unsigned long long>()) +
        " is outside [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  }
  const long long x = v.get<long long>();
  if (x < lo || x > hi) {
    throw "control '" + key + "' = " + std::to_string(x) + " is outside [" + std::to_string(lo) +
        ", " + std::to_string(hi) + "]";
  }
  return static_cast<int>(x);
}

bool Bool(const json& v, const std::string& key) {
  if (!v.is_boolean()) throw std::string("control '" + key + "' must be true or false");
  return v.get<bool>();
}

// The scene spec with its query parameters replaced by `params` (merged).
std::string WithSceneParameters(const std::string& spec, const json& params) {
  const auto q = spec.find('?');
  std::map<std::string, std::string> query;
  if (q != std::string::npos) {
    std::stringstream rest(spec.substr(q + 1));
    std::string item;
    while (std::getline(rest, item, '&')) {
      const auto eq = item.find('=');
      if (eq != std::string::npos) query[item.substr(0, eq)] = item.substr(eq + 1);
    }
  }
  for (const auto& [key, value] : params.items()) {
    if (key.empty() || key.size() > 64 ||
        key.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789_") != std::string::npos) {
      throw std::string("scene parameter names are lower-case words, got '" + key + "'");
    }
    std::string text;
    if (value.is_number()) {
      const double x = value.get<double>();
      if (!std::isfinite(x)) throw std::string("scene parameter '" + key + "' must be finite");
      std::ostringstream s;
      s.precision(9);
      s << x;
      text = s.str();
    } else if (value.is_string() && value.get<std::string>().size() <= 64 &&
               value.get<std::string>().find_first_of("&?=") == std::string::npos) {
      text = value.get<std::string>();
    } else {
      throw std::string("scene parameter '" + key + "' must be a number or a short string");
    }
    query[key] = text;
  }
  std::string out = spec.substr(0, q);
  char sep = '?';
  for (const auto& [key, value] : query) {
    out += sep + key + "=" + value;
    sep = '&';
  }
  return out;
}

void Append(std::string& out, const void* data, std::size_t bytes) {
  out.append(static_cast<const char*>(data), bytes);
}

}  // namespace

void ViewerOptions::Validate() const {
  if (port < 0 || port > 65535) {
    throw Error(ErrorCode::kInvalidArgument,
                "--port " + std::to_string(port) + " must be in [0, 65535] (0 = any free port)");
  }
  if (bind_address.empty()) throw Error(ErrorCode::kInvalidArgument, "--bind must not be empty");
  if (max_body_bytes < 1024) {
    throw Error(ErrorCode::kInvalidArgument, "max_body_bytes must be >= 1024");
  }
  if (max_frames < 0) throw Error(ErrorCode::kInvalidArgument, "--frames must be >= 0");
}

struct ViewerServer::Impl {
  ViewerOptions options;
  CameraOpener opener;
  // The loop's source. camera_mutex guards the pointer (the loop replaces it on a scene change)
  // against Stop(), which interrupts a Grab() waiting for a silent live source.
  std::mutex camera_mutex;
  std::unique_ptr<Camera> camera;
  CameraInfo info;
  bool pan_supported = false;
  std::string three_js, orbit_js;
  // This server instance's id: a page left open across a restart sees it change and reloads
  // (frame numbers start again at 1, and the camera may be another).
  std::string session;

  // Control state (HTTP threads write, the loop reads).
  mutable std::mutex control_mutex;
  Desired desired;

  // The latest frame (the loop writes, HTTP threads read).
  mutable std::mutex frame_mutex;
  std::condition_variable frame_cv;
  std::shared_ptr<const std::string> latest;
  long long latest_seq = 0;
  PointCloud latest_cloud;
  // /cloud.ply asks the loop for the last frame's cloud (copied only then: 8 MB per VGA frame).
  long long cloud_requested = 0, cloud_served = 0;
  ViewerStatus status;
  std::map<std::string, long long> dropped_by_client;

  std::atomic<bool> stopping{false};
  std::atomic<bool> finished{false};
  std::mutex done_mutex;
  std::condition_variable done_cv;

  httplib::Server server;
  int port = 0;
  std::thread http_thread, loop_thread;

  std::string MetaJson() const;
  std::string RaysBinary(const Pipeline& pipeline) const;
  std::string rays;  // built once by the constructor
  std::string Control(const std::string& body);
  std::string Stage(const json& j, Staged& s) const;
  void CheckRecordDir() const;
  void Loop();
  void Routes();
  bool HostAllowed(const httplib::Request& req) const;
};

bool ViewerServer::Impl::HostAllowed(const httplib::Request& req) const {
  const std::string host = req.get_header_value("Host");
  const std::string p = ":" + std::to_string(port);
  const std::string& bind = options.bind_address;
  // Any 127.x.y.z is loopback, not only 127.0.0.1.
  const bool loopback = bind == "localhost" || bind == "::1" || bind.rfind("127.", 0) == 0;
  const bool wildcard = bind == "0.0.0.0" || bind == "::";
  const bool as_bound = host == bind + p || host == "[" + bind + "]" + p;
  bool ok;
  if (loopback) {
    ok = as_bound || host == "127.0.0.1" + p || host == "localhost" + p || host == "[::1]" + p;
  } else if (!wildcard) {
    // One address: the page is opened by that address. A name that a foreign site resolves
    // to it (DNS rebinding) is refused.
    ok = as_bound;
  } else {
    ok = !host.empty();  // every address of this machine, by any name (docs/viewer.md)
  }
  const std::string origin = req.get_header_value("Origin");
  // A page of another origin (DNS rebinding, a foreign site) must not steer the camera.
  if (!origin.empty() && origin != "http://" + host) ok = false;
  return ok;
}

std::string ViewerServer::Impl::MetaJson() const {
  json m;
  m["camera"] = options.camera_spec;
  m["session"] = session;
  m["model"] = info.model;
  m["width"] = info.width();
  m["height"] = info.height();
  m["range_m"] = info.unambiguous_range_m();
  m["has_truth"] = info.has_ground_truth;
  m["has_intensity"] = info.has_intensity;
  m["pan_supported"] = pan_supported;
  m["scene_parameters_supported"] = options.camera_spec.rfind("sim:", 0) == 0;
  m["min_register"] = info.min_integration_register;
  m["max_register"] = info.max_integration_register;
  m["three_js"] = !three_js.empty();
  // The false-colour law (tofcam/color/false_color.h) for the legend, 64 steps over [0, L].
  json legend = json::array();
  const double far = info.unambiguous_range_m();
  for (int k = 0; k < 64; ++k) {
    const Rgb8 c = FalseColorOfDistance(far * k / 63.0, 0.0, far);
    legend.push_back({c.r, c.g, c.b});
  }
  m["legend"] = legend;
  m["reject_mask"] = kRejectMask;
  json flags = json::array();
  for (Flag f : kAllFlags) {
    flags.push_back({{"bit", static_cast<unsigned>(f)}, {"name", std::string(FlagName(f))}});
  }
  m["flags"] = flags;
  std::lock_guard<std::mutex> lock(control_mutex);
  const PipelineOptions& p = desired.pipeline;
  m["controller"] =
      p.controller_enabled ? std::string(ControllerKindName(p.controller.kind)) : "none";
  m["target_intensity"] = p.controller.target_intensity;
  m["gain_register_per_intensity"] = p.controller.gain_register_per_intensity;
  m["bias_register"] = p.controller.bias_register;
  m["filters"] = {{"saturation", p.filters.saturation_enabled},
                  {"accuracy", p.filters.accuracy_enabled},
                  {"amplitude", p.filters.amplitude_enabled},
                  {"jump_edge", p.filters.jump_edge_enabled},
                  {"flying_pixel", p.filters.flying_pixel_enabled},
                  {"weingarten", p.filters.weingarten_enabled},
                  {"uncertainty", p.uncertainty_enabled},
                  {"denoise", p.denoise_enabled},
                  {"prediction", p.prediction_enabled}};
  m["max_delta_l_m"] = p.filters.accuracy.max_delta_l_m;
  m["min_amplitude"] = p.filters.amplitude.min_amplitude;
  m["max_uncertainty_m"] = p.uncertainty.max_uncertainty_m;
  return m.dump();
}

std::string ViewerServer::Impl::RaysBinary(const Pipeline& pipeline) const {
  const RayTable& r = pipeline.rays();
  std::string out;
  for (const Image<float>* c : {&r.x, &r.y, &r.z}) Append(out, c->data(), c->size() * 4);
  return out;
}

// The request's controls applied to a copy of the desired state (the caller holds the lock), or
// the 400 reason. Run again after a scene reopens: whatever other requests committed meanwhile is
// the base then, so a slow scene change never writes back a state older than theirs.
std::string ViewerServer::Impl::Stage(const json& j, Staged& s) const {
  s = Staged{};
  s.pipeline = desired.pipeline;
  s.paused = desired.paused;
  s.step = desired.step;
  s.pan = desired.pan_rad;
  s.record = desired.record;
  s.spec = desired.camera_spec;
  int steps = 0;
  try {
    for (const auto& [key, v] : j.items()) {
      PipelineOptions& p = s.pipeline;
      if (key == "paused") {
        s.paused = Bool(v, key);
      } else if (key == "step") {
        steps = Integer(v, key, 1, kMaxSteps);
      } else if (key == "controller") {
        if (!v.is_string()) throw std::string("control 'controller' must be a string");
        if (v.get<std::string>() == "none") {
          p.controller_enabled = false;
        } else {
          try {
            p.controller.kind = ParseControllerKind(v.get<std::string>());
          } catch (const Error& e) {
            throw std::string(e.what());
          }
          p.controller_enabled = true;
        }
      } else if (key == "target_intensity") {
        p.controller.target_intensity = Number(v, key, 0.0, 65532.0, true);
      } else if (key == "gain_register_per_intensity") {
        p.controller.gain_register_per_intensity = Number(v, key, 0.0, 1.0);
      } else if (key == "bias_register") {
        p.controller.bias_register = Integer(v, key, 1, 65535);
      } else if (key == "fixed_register") {
        const int lo = std::max(1, info.min_integration_register);
        if (info.max_integration_register < lo) {
          throw std::string("this source's integration time cannot be set");
        }
        p.controller_enabled = true;
        p.controller.kind = ControllerKind::kFixed;
        p.controller.bias_register = Integer(v, key, lo, info.max_integration_register);
      } else if (key == "filters") {
        if (!v.is_object()) throw std::string("control 'filters' must be an object");
        for (const auto& [name, on] : v.items()) {
          const bool b = Bool(on, "filters." + name);
          if (name == "saturation") {
            p.filters.saturation_enabled = b;
          } else if (name == "accuracy") {
            p.filters.accuracy_enabled = b;
            if (b) p.accuracy_enabled = true;
          } else if (name == "amplitude") {
            p.filters.amplitude_enabled = b;
          } else if (name == "jump_edge") {
            p.filters.jump_edge_enabled = b;
          } else if (name == "flying_pixel") {
            p.filters.flying_pixel_enabled = b;
          } else if (name == "weingarten") {
            p.filters.weingarten_enabled = b;
          } else if (name == "uncertainty") {
            p.uncertainty_enabled = b;
            if (b) p.accuracy_enabled = true;
          } else if (name == "denoise") {
            // Not a filter but a stage before them (docs/beyond.md); toggled with them.
            p.denoise_enabled = b;
            if (b) p.accuracy_enabled = true;
          } else if (name == "prediction") {
            // The neighbours' prediction: the uncertainty judges residuals, kept pixels are
            // combined with it (docs/beyond.md). On, it brings ΔL and the uncertainty that
            // judges against it; off, the uncertainty cannot judge a combination that is gone.
            p.prediction_enabled = b;
            if (b) {
              p.accuracy_enabled = true;
              p.uncertainty_enabled = true;
            } else {
              p.uncertainty.judge_combination = false;
            }
          } else {
            throw std::string("unknown filter '" + name + "'");
          }
        }
      } else if (key == "max_delta_l_m") {
        p.filters.accuracy.max_delta_l_m = Number(v, key, 0.0, 100.0, true);
      } else if (key == "min_amplitude") {
        p.filters.amplitude.min_amplitude = Number(v, key, 0.0, 65532.0);
      } else if (key == "max_uncertainty_m") {
        p.uncertainty.max_uncertainty_m = Number(v, key, 0.0, 100.0, true);
      } else if (key == "pan_deg") {
        if (!pan_supported) throw std::string("this source has no pan unit");
        s.pan = Number(v, key, -180.0, 180.0) * M_PI / 180.0;
      } else if (key == "scene") {
        if (options.camera_spec.rfind("sim:", 0) != 0) {
          throw std::string("scene parameters need a simulated source (sim:...)");
        }
        if (!v.is_object() || v.size() > 16) {
          throw std::string("control 'scene' must be an object of at most 16 parameters");
        }
        s.spec = WithSceneParameters(s.spec, v);
        s.reopen = true;
      } else if (key == "record") {
        if (!v.is_string() || (v != "start" && v != "stop")) {
          throw std::string("control 'record' must be \"start\" or \"stop\"");
        }
        s.record = v == "start" ? 1 : -1;
        if (s.record > 0) CheckRecordDir();
      } else {
        throw std::string("unknown control '" + key + "'");
      }
    }
    // Single frames are for a paused camera: while running, steps would pile up and run on
    // after the next pause. Resuming drops the ones left.
    if (steps > 0) {
      if (!s.paused) throw std::string("control 'step' needs the camera paused");
      s.step = std::min(s.step + steps, kMaxSteps);
    }
    if (!s.paused) s.step = 0;
    try {
      // Everything the pipeline checks against this camera (register bounds, calibration), so
      // the loop never meets a configuration it cannot build.
      const Pipeline probe(s.pipeline, info);
    } catch (const Error& e) {
      throw std::string(e.what());
    }
  } catch (const std::string& reason) {
    return reason;
  }
  // Any pipeline key rebuilds the pipeline at the next frame (the controller continues from the
  // current register); pause, step, pan and recording do not.
  s.changed = std::any_of(j.items().begin(), j.items().end(), [](const auto& item) {
    const std::string& k = item.key();
    return k != "paused" && k != "step" && k != "pan_deg" && k != "record" && k != "scene";
  });
  return "";
}

// Recordings are begun by the camera loop; a directory that cannot take one is refused here, so
// that the page hears of it (a 400) instead of a button that says "recording".
void ViewerServer::Impl::CheckRecordDir() const {
  std::error_code ec, is_dir_ec;  // the throwing overloads would turn the 400 into a 500
  std::filesystem::create_directories(options.record_dir, ec);
  if (ec || !std::filesystem::is_directory(options.record_dir, is_dir_ec) ||
      ::access(options.record_dir.c_str(), W_OK) != 0) {
    throw std::string(
        "recording: cannot write to " + options.record_dir.string() +
        (ec ? " (" + ec.message() + ")" : std::string(" (not a writable directory)")));
  }
}

std::string ViewerServer::Impl::Control(const std::string& body) {
  json j;
  try {
    j = json::parse(body);
  } catch (const json::exception&) {
    return "the body is not valid JSON";
  }
  if (!j.is_object()) return "the body must be a JSON object of controls";
  std::unique_lock<std::mutex> lock(control_mutex);
  Staged s;
  if (std::string reason = Stage(j, s); !reason.empty()) return reason;
  std::unique_ptr<Camera> reopened;
  for (int attempt = 0; s.reopen; ++attempt) {
    // Opening a simulator takes a moment: not under the lock the loop takes every frame.
    const std::string opening = s.spec;
    lock.unlock();
    try {
      reopened = opener(opening);
    } catch (const Error& e) {
      return std::string("scene: ") + e.what();
    }
    const CameraInfo& i = reopened->Info();
    if (i.width() != info.width() || i.height() != info.height()) {
      return "scene: the reopened camera has another size";
    }
    lock.lock();
    // Staged again on what other requests committed meanwhile (they are kept).
    if (std::string reason = Stage(j, s); !reason.empty()) return reason;
    if (s.spec == opening) break;
    if (attempt == 2) return "scene: other scene changes kept arriving; send it again";
  }
  desired.pipeline = std::move(s.pipeline);
  if (s.changed) ++desired.pipeline_version;
  desired.paused = s.paused;
  desired.step = s.step;
  desired.pan_rad = s.pan;
  desired.record = s.record;
  if (s.reopen) {
    desired.camera = std::move(reopened);
    desired.camera_spec = s.spec;
  }
  return "";
}

void ViewerServer::Impl::Loop() {
  std::uint64_t applied_version = 0;
  std::optional<Pipeline> pipeline;
  std::unique_ptr<RecordingWriter> recorder;
  std::string recording_path;
  PipelineResult result;
  std::deque<Clock::time_point> times;
  const double cpu_start = CpuSeconds();
  long long frames = 0;
  int reg = 0;
  while (!stopping) {
    bool paused = false, step = false;
    std::optional<double> pan;
    int record = 0;
    std::unique_ptr<Camera> reopened;
    {
      std::lock_guard<std::mutex> lock(control_mutex);
      if (!pipeline || desired.pipeline_version != applied_version) {
        PipelineOptions p = desired.pipeline;
        p.color_legend = false;  // the page draws its own legend
        applied_version = desired.pipeline_version;
        try {
          Pipeline fresh(std::move(p), info);  // the old one stays if this throws
          pipeline.emplace(std::move(fresh));
        } catch (const std::exception& e) {
          std::lock_guard<std::mutex> frame_lock(frame_mutex);
          status.last_error = std::string("pipeline: ") + e.what();
          ++status.errors;
        }
        if (!pipeline) {
          std::this_thread::sleep_for(std::chrono::milliseconds(50));
          continue;
        }
        if (reg == 0) reg = pipeline->InitialIntegrationRegister();
        if (pipeline->options().controller_enabled &&
            pipeline->options().controller.kind == ControllerKind::kFixed) {
          reg = pipeline->InitialIntegrationRegister();
        }
        pipeline->ResetController(reg);
      }
      paused = desired.paused;
      if (paused && desired.step > 0) {
        step = true;
        --desired.step;
      }
      pan = desired.pan_rad;
      desired.pan_rad.reset();
      record = desired.record;
      desired.record = 0;
      reopened = std::move(desired.camera);
    }
    if (reopened) {
      {
        std::lock_guard<std::mutex> lock(camera_mutex);
        camera = std::move(reopened);
      }
      // A new source (e.g. the simulator with other scene parameters) starts its own clock, so
      // a recording that went on would have timestamps that decrease, which a recording may
      // not (RecordingWriter refuses them). The current file is finished and a new one begun.
      if (recorder && record >= 0) record = 2;  // unless the same request stops recording
    }
    if (pan) {
      try {
        camera->SetPanAngleRad(*pan);
      } catch (const Error& e) {
        std::lock_guard<std::mutex> lock(frame_mutex);
        status.last_error = e.what();
        ++status.errors;
      }
    }
    // record: 1 start, -1 stop, 2 finish the current file and start the next.
    if ((record < 0 || record == 2) && recorder) {
      try {
        recorder->Close();
      } catch (const Error& e) {
        std::lock_guard<std::mutex> lock(frame_mutex);
        status.last_error = std::string("recording: ") + e.what();
        ++status.errors;
      }
      recorder.reset();
      recording_path.clear();
    }
    if (record > 0 && !recorder) {
      try {
        std::filesystem::create_directories(options.record_dir);
        // view_<unix time>.h5, or _2, _3, ... after it: a second file in the same second must
        // not overwrite the first.
        const std::string stem = "view_" + std::to_string(std::time(nullptr));
        std::filesystem::path path = options.record_dir / (stem + ".h5");
        for (int k = 2; std::filesystem::exists(path); ++k) {
          path = options.record_dir / (stem + "_" + std::to_string(k) + ".h5");
        }
        recording_path = path.string();
        recorder = std::make_unique<RecordingWriter>(recording_path, info);
      } catch (const std::exception& e) {
        std::lock_guard<std::mutex> lock(frame_mutex);
        status.last_error = std::string("recording: ") + e.what();
        ++status.errors;
        recording_path.clear();
      }
    }
    {
      std::lock_guard<std::mutex> lock(frame_mutex);
      status.paused = paused;
      status.recording = recording_path;
      if (cloud_served < cloud_requested && latest_seq > 0) {
        latest_cloud = result.cloud;  // the last processed frame's, also while paused
        cloud_served = cloud_requested;
        frame_cv.notify_all();
      }
    }
    if (paused && !step) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      continue;
    }
    std::optional<Frame> frame;
    try {
      camera->SetIntegrationTimeRegister(
          std::clamp(reg, info.min_integration_register, info.max_integration_register));
    } catch (const Error&) {
      // A recording or an import: nothing to set.
    }
    try {
      frame = camera->Grab();
    } catch (const Error& e) {
      std::lock_guard<std::mutex> lock(frame_mutex);
      status.last_error = e.what();
      ++status.errors;
      frame.reset();
    }
    if (!frame) {
      {
        std::lock_guard<std::mutex> lock(frame_mutex);
        status.ended = true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }
    try {
      pipeline->Process(*frame, result);
      reg = result.next_integration_register;
      if (result.next_modulation_frequency_hz != frame->info.modulation_frequency_hz) {
        camera->SetModulationFrequencyHz(result.next_modulation_frequency_hz);
      }
    } catch (const std::exception& e) {
      // A frame the pipeline refuses (e.g. a source that changed its size) is reported and
      // skipped; the server keeps serving the last good frame.
      std::lock_guard<std::mutex> lock(frame_mutex);
      status.last_error = e.what();
      ++status.errors;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }
    if (recorder) {
      try {
        recorder->Append(*frame);
      } catch (const std::exception& e) {
        std::lock_guard<std::mutex> lock(frame_mutex);
        status.last_error = std::string("recording: ") + e.what();
        ++status.errors;
        recorder.reset();
        recording_path.clear();
      }
    }
    ++frames;
    const Clock::time_point now = Clock::now();
    times.push_back(now);
    while (!times.empty() && now - times.front() > std::chrono::seconds(1)) times.pop_front();
    const double fps = static_cast<double>(times.size());

    // The message: a JSON header, then the planes (docs/viewer.md).
    const MetricFrame& m = result.frame;
    const int w = m.width(), h = m.height();
    const std::size_t n = static_cast<std::size_t>(w) * h;
    const Image<Rgb8> raw = pipeline->RenderRaw(result);
    const Image<Rgb8> filtered = pipeline->RenderFiltered(result);
    std::string body;
    json header;
    json list = json::array();
    const auto add = [&](const std::string& name, const char* type, const void* data,
                         std::size_t bytes) {
      while (body.size() % 4 != 0) body.push_back('\0');
      list.push_back({{"name", name}, {"type", type}, {"offset", body.size()}, {"bytes", bytes}});
      Append(body, data, bytes);
    };
    add("raw_rgb", "u8", raw.data(), n * 3);
    add("filtered_rgb", "u8", filtered.data(), n * 3);
    add("distance_m", "f32", m.radial_distance_m.data(), n * 4);
    add("amplitude", "f32", m.amplitude.data(), n * 4);
    if (m.has_intensity()) add("intensity", "f32", m.intensity.data(), n * 4);
    if (!m.delta_l_m.empty()) add("delta_l_m", "f32", m.delta_l_m.data(), n * 4);
    add("flags", "u16", m.flags.data(), n * 2);
    add("input_flags", "u16", result.input_flags.data(), n * 2);
    if (m.truth) {
      std::vector<float> error(n);
      for (std::size_t i = 0; i < n; ++i) {
        error[i] = m.radial_distance_m[i] - m.truth->radial_distance_m[i];
      }
      add("error_m", "f32", error.data(), n * 4);
    }
    const FrameStats& s = result.stats;
    header["width"] = w;
    header["height"] = h;
    header["timestamp_s"] = s.timestamp_s;
    header["register"] = s.integration_time_register;
    header["integration_time_us"] = s.integration_time_us;
    header["next_register"] = result.next_integration_register;
    header["mean_intensity"] = Finite(s.mean_intensity);
    header["target_intensity"] = pipeline->options().controller.target_intensity;
    header["valid_fraction"] = Finite(s.valid_fraction);
    header["mean_delta_l_m"] = Finite(s.mean_delta_l_m);
    header["rmse_m"] = m.truth ? Finite(s.rmse_m) : json(nullptr);
    header["frames_per_s"] = fps;
    header["controller"] = std::string(pipeline->ControllerName());
    header["pan_deg"] = frame->info.pan_angle_rad * 180.0 / M_PI;
    header["modulation_frequency_hz"] = frame->info.modulation_frequency_hz;
    header["range_m"] = UnambiguousRangeM(frame->info.modulation_frequency_hz);
    header["planes"] = list;
    {
      std::lock_guard<std::mutex> lock(frame_mutex);
      header["seq"] = latest_seq + 1;
      header["recording"] = recording_path;
      header["dropped"] = status.dropped;
      header["last_error"] = status.last_error;
      header["errors"] = status.errors;
      header["session"] = session;
    }
    std::string head = header.dump();
    while ((head.size() + 12) % 8 != 0) head.push_back(' ');
    auto message = std::make_shared<std::string>();
    message->reserve(12 + head.size() + body.size());
    const std::uint32_t prefix[3] = {kMagic, kFormatVersion,
                                     static_cast<std::uint32_t>(head.size())};
    Append(*message, prefix, sizeof prefix);
    message->append(head);
    message->append(body);
    {
      std::lock_guard<std::mutex> lock(frame_mutex);
      latest = std::move(message);
      ++latest_seq;

      status.frames = frames;
      status.frames_per_s = fps;
      status.valid_fraction = s.valid_fraction;
      status.controller = std::string(pipeline->ControllerName());
      status.cpu_ms_per_frame = 1e3 * (CpuSeconds() - cpu_start) / frames;
      status.ended = false;
    }
    frame_cv.notify_all();
    if (options.max_frames > 0 && frames >= options.max_frames) break;
  }
  if (recorder) {
    try {
      recorder->Close();
    } catch (const Error&) {
    }
  }
  finished = true;
  done_cv.notify_all();
}

void ViewerServer::Impl::Routes() {
  server.set_payload_max_length(options.max_body_bytes);
  server.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
    if (!HostAllowed(req)) {
      res.status = 403;
      res.set_content("forbidden: foreign Host or Origin\n", "text/plain");
      return httplib::Server::HandlerResponse::Handled;
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  server.set_error_handler([](const httplib::Request&, httplib::Response& res) {
    if (res.body.empty()) {
      res.set_content("HTTP " + std::to_string(res.status) + "\n", "text/plain");
    }
  });
  const auto text = [](httplib::Response& res, const char* body, const char* type) {
    res.set_content(body, type);
    res.set_header("Cache-Control", "no-store");
  };
  server.Get("/", [text](const httplib::Request&, httplib::Response& res) {
    text(res, assets::kIndexHtml, "text/html; charset=utf-8");
  });
  server.Get("/viewer.js", [text](const httplib::Request&, httplib::Response& res) {
    text(res, assets::kViewerJs, "text/javascript; charset=utf-8");
  });
  server.Get("/three.min.js", [this](const httplib::Request&, httplib::Response& res) {
    if (three_js.empty()) {
      res.status = 404;
      res.set_content("three.js is not installed (apt-get install libjs-three)\n", "text/plain");
      return;
    }
    res.set_content(three_js, "text/javascript");
  });
  server.Get("/OrbitControls.js", [this](const httplib::Request&, httplib::Response& res) {
    if (orbit_js.empty()) {
      res.status = 404;
      res.set_content("OrbitControls.js is not installed (apt-get install libjs-three)\n",
                      "text/plain");
      return;
    }
    res.set_content(orbit_js, "text/javascript");
  });
  server.Get("/meta", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(MetaJson(), "application/json");
  });
  server.Get("/rays", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(rays, "application/octet-stream");
  });
  server.Get("/status", [this](const httplib::Request&, httplib::Response& res) {
    const ViewerStatus s = [this] {
      std::lock_guard<std::mutex> lock(frame_mutex);
      return status;
    }();
    json j = {{"frames", s.frames},
              {"frames_per_s", s.frames_per_s},
              {"valid_fraction", s.valid_fraction},
              {"dropped", s.dropped},
              {"served", s.served},
              {"cpu_ms_per_frame", s.cpu_ms_per_frame},
              {"paused", s.paused},
              {"ended", s.ended},
              {"controller", s.controller},
              {"recording", s.recording},
              {"last_error", s.last_error},
              {"errors", s.errors}};
    res.set_content(j.dump(), "application/json");
    res.set_header("Cache-Control", "no-store");
  });
  server.Get("/frame", [this](const httplib::Request& req, httplib::Response& res) {
    long long after = 0;
    const std::string a = req.get_param_value("after");
    if (!a.empty()) {
      char* end = nullptr;
      after = std::strtoll(a.c_str(), &end, 10);
      if (end == a.c_str() || *end != '\0' || after < 0) {
        res.status = 400;
        res.set_content("after must be a frame number >= 0\n", "text/plain");
        return;
      }
    }
    const std::string client = req.get_param_value("client");
    if (client.size() > 64 ||
        client.find_first_not_of(
            "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") !=
            std::string::npos) {
      res.status = 400;
      res.set_content("client must be at most 64 letters, digits, '-' or '_'\n", "text/plain");
      return;
    }
    std::unique_lock<std::mutex> lock(frame_mutex);
    // A frame number this server never sent comes from a page of an earlier server on this
    // port: it gets the latest frame at once (whose session tells it to start over).
    if (after > latest_seq) after = 0;
    frame_cv.wait_for(lock, std::chrono::seconds(2),
                      [&] { return latest_seq > after || stopping.load(); });
    if (latest_seq <= after || !latest) {
      res.status = 204;
      return;
    }
    const std::shared_ptr<const std::string> message = latest;
    // Frames this client did not fetch: it was slower than the camera.
    if (after > 0 && latest_seq > after + 1) {
      const long long skipped = latest_seq - after - 1;
      status.dropped += skipped;
      if (!client.empty() && (dropped_by_client.size() < 1024 || dropped_by_client.count(client))) {
        dropped_by_client[client] += skipped;
      }
    }
    ++status.served;
    lock.unlock();
    // Streamed from the shared message: no copy of a frame per client.
    res.set_content_provider(
        message->size(), "application/octet-stream",
        [message](std::size_t offset, std::size_t length, httplib::DataSink& sink) {
          sink.write(message->data() + offset, length);
          return true;
        });
    res.set_header("Cache-Control", "no-store");
  });
  server.Get("/cloud.ply", [this](const httplib::Request&, httplib::Response& res) {
    PointCloud cloud;
    {
      std::unique_lock<std::mutex> lock(frame_mutex);
      const long long mine = ++cloud_requested;
      frame_cv.wait_for(lock, std::chrono::seconds(2),
                        [&] { return cloud_served >= mine || stopping.load(); });
      if (cloud_served >= mine) cloud = latest_cloud;
    }
    if (cloud.empty()) {
      res.status = 404;
      res.set_content("no cloud (the camera is paused or ended, or the point cloud stage is off)\n",
                      "text/plain");
      return;
    }
    const std::filesystem::path tmp =
        std::filesystem::temp_directory_path() /
        ("tofcam_view_" + std::to_string(::getpid()) + "_" +
         std::to_string(std::hash<std::thread::id>{}(std::this_thread::get_id())) + ".ply");
    try {
      WritePly(tmp, cloud, PlyFormat::kBinary, /*only_valid=*/true);
    } catch (const Error& e) {
      res.status = 500;
      res.set_content(std::string(e.what()) + "\n", "text/plain");
      return;
    }
    res.set_content(ReadWholeFile(tmp), "application/octet-stream");
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    res.set_header("Content-Disposition", "attachment; filename=\"tofcam_cloud.ply\"");
  });
  server.Post("/control", [this](const httplib::Request& req, httplib::Response& res) {
    const std::string reason = Control(req.body);
    if (!reason.empty()) {
      res.status = 400;
      res.set_content(json({{"error", reason}}).dump(), "application/json");
      return;
    }
    res.set_content(R"({"ok":true})", "application/json");
  });
}

ViewerServer::ViewerServer(const ViewerOptions& options, const PipelineOptions& pipeline,
                           CameraOpener opener)
    : impl_(std::make_unique<Impl>()) {
  options.Validate();
  Impl& d = *impl_;
  d.options = options;
  d.opener = std::move(opener);
  d.camera = d.opener(options.camera_spec);
  d.info = d.camera->Info();
  // Asked, not probed: setting the current angle would succeed on sources that cannot turn
  // (a recording repeats its angles) and would freeze a simulated pan schedule.
  d.pan_supported = d.camera->HasPanUnit();
  d.desired.pipeline = pipeline;
  d.desired.camera_spec = options.camera_spec;
  d.session = std::to_string(::getpid()) + "-" +
              std::to_string(std::chrono::system_clock::now().time_since_epoch().count());
  // Validates the pipeline against the camera now, so a bad option fails before serving.
  const Pipeline probe(pipeline, d.info);
  d.rays = d.RaysBinary(probe);
  d.three_js = ReadWholeFile(options.three_js_dir / "three.min.js");
  d.orbit_js = ReadWholeFile(options.three_js_dir / "examples/js/controls/OrbitControls.js");
  d.Routes();
  if (options.port == 0) {
    d.port = d.server.bind_to_any_port(options.bind_address);
  } else {
    d.port = d.server.bind_to_port(options.bind_address, options.port) ? options.port : -1;
  }
  if (d.port <= 0) {
    throw Error(ErrorCode::kIo, "cannot listen on " + options.bind_address + ":" +
                                    std::to_string(options.port) +
                                    " (in use, or not an address of this machine)");
  }
}

ViewerServer::~ViewerServer() { Stop(); }

int ViewerServer::port() const noexcept { return impl_->port; }

void ViewerServer::Start() {
  Impl& d = *impl_;
  d.loop_thread = std::thread([&d] { d.Loop(); });
  d.http_thread = std::thread([&d] { d.server.listen_after_bind(); });
}

bool ViewerServer::WaitFor(double seconds) {
  Impl& d = *impl_;
  std::unique_lock<std::mutex> lock(d.done_mutex);
  return d.done_cv.wait_for(lock, std::chrono::duration<double>(seconds),
                            [&d] { return d.finished.load() || d.stopping.load(); });
}

void ViewerServer::Stop() {
  Impl& d = *impl_;
  d.stopping = true;
  {
    std::lock_guard<std::mutex> lock(d.camera_mutex);
    if (d.camera) d.camera->Interrupt();  // a ROS 2 source may be waiting up to its timeout
  }
  d.frame_cv.notify_all();
  d.done_cv.notify_all();
  d.server.stop();
  if (d.loop_thread.joinable()) d.loop_thread.join();
  if (d.http_thread.joinable()) d.http_thread.join();
}

std::string ViewerServer::ApplyControl(const std::string& json_body) {
  return impl_->Control(json_body);
}

ViewerStatus ViewerServer::Status() const {
  std::lock_guard<std::mutex> lock(impl_->frame_mutex);
  return impl_->status;
}

}  // namespace tofcam::viewer

#pragma once
// The live viewer of `tofcam view` (issue 17, docs/viewer.md): a camera loop that runs the
// pipeline at camera rate, and an HTTP server (cpp-httplib) on loopback that serves one page,
// the latest frame as binary, the status, the current cloud as PLY, and takes control changes
// that apply to the next frame. A slow or closed browser never blocks the loop: every client
// reads the latest frame when it asks and the frames it skipped are counted as dropped.
//
// Routes: GET / (the page), /viewer.js, /three.min.js, /OrbitControls.js (from libjs-three),
// /meta (camera, legend, JSON), /rays (unit rays, binary), /frame?after=N&client=ID (binary,
// long poll up to 2 s, 204 when nothing new), /status (JSON), /cloud.ply; POST /control (JSON).
// Anything else is 404; a Host or Origin header that is not this server's is 403; a body over
// max_body_bytes is 413; a malformed or out-of-range control is 400 with a one-line reason.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "tofcam/core/camera.h"
#include "tofcam/pipeline/pipeline.h"

namespace tofcam::viewer {

struct ViewerOptions {
  std::string bind_address = "127.0.0.1";         ///< Loopback by default.
  int port = 8080;                                ///< 0 = any free port (see ViewerServer::port()).
  std::string camera_spec;                        ///< The source, e.g. "sim:demo" (shown; reopened
                                                  ///< with new scene parameters when they change).
  std::filesystem::path record_dir = "out/view";  ///< Recordings go here (created on demand).
  /// Where Debian's libjs-three installs three.js.
  std::filesystem::path three_js_dir = "/usr/share/javascript/three";
  std::size_t max_body_bytes = 64 * 1024;  ///< Larger request bodies get 413.
  long long max_frames = 0;                ///< Stop after this many frames; 0 = until Stop().
  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// Opens a camera from a spec (the CLI's OpenCamera with its source options).
using CameraOpener = std::function<std::unique_ptr<Camera>(const std::string& spec)>;

/// What the server reports on /status (and the loop keeps for tests).
struct ViewerStatus {
  long long frames = 0;           ///< Frames processed.
  double frames_per_s = 0.0;      ///< Over the last second.
  double valid_fraction = 0.0;    ///< Of the last frame, after the filters.
  long long dropped = 0;          ///< Frames clients skipped (all clients).
  long long served = 0;           ///< Frames sent to clients.
  double cpu_ms_per_frame = 0.0;  ///< Process CPU time per processed frame, ms.
  bool paused = false;
  bool ended = false;      ///< The source ran out of frames.
  std::string controller;  ///< "" when off.
  std::string recording;   ///< Path being recorded, "" when not.
  std::string last_error;  ///< Last error of the camera loop (e.g. a failed recording).
  long long errors = 0;    ///< Errors of the camera loop so far (last_error is the newest).
};

class ViewerServer {
 public:
  /// Opens the camera, builds the pipeline and binds the port. Throws the opener's and the
  /// pipeline's errors, Error(kInvalidArgument) for bad options, Error(kIo) when the port cannot
  /// be bound.
  ViewerServer(const ViewerOptions& options, const PipelineOptions& pipeline, CameraOpener opener);
  ~ViewerServer();  ///< Stops and joins.
  ViewerServer(const ViewerServer&) = delete;
  ViewerServer& operator=(const ViewerServer&) = delete;

  /// The bound port (the one chosen when options.port was 0).
  [[nodiscard]] int port() const noexcept;
  /// Starts the camera loop and the HTTP server on their own threads; returns at once.
  void Start();
  /// Waits up to `seconds` for Stop() or max_frames processed frames; true when one happened
  /// (the server keeps serving the last frame until Stop()).
  bool WaitFor(double seconds);
  /// Stops both; idempotent, callable from any thread (e.g. a signal watcher).
  void Stop();

  /// Applies a control body as POST /control does. Returns "" when accepted (it takes effect
  /// at the next frame), else the one-line reason.
  [[nodiscard]] std::string ApplyControl(const std::string& json_body);
  [[nodiscard]] ViewerStatus Status() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tofcam::viewer

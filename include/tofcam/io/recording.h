#pragma once
/// \file
/// Recordings: one HDF5 file per frame sequence (layout in docs/recording-format.md), written
/// frame by frame so that a killed recorder leaves a readable file that loses at most the frame in
/// flight; read back frame-exactly by RecordingReader and served as a Camera by PlaybackCamera.
///
/// A recording is appended in place (not through AtomicFile) on purpose: the frames written so
/// far must survive a crash. Every reader validates types, sizes and ranges before use; a
/// truncated, corrupted or hostile file ends in Error(kFormat) naming the file and the problem.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tofcam/core/camera.h"
#include "tofcam/core/frame.h"

namespace tofcam {

/// Current recording format version (root attribute `format_version`).
inline constexpr int kRecordingFormatVersion = 1;

/// How a recording is written.
struct RecordingOptions {
  /// Deflate (gzip) level 0..9 of the image datasets; 0 stores them uncompressed.
  int compression_level = 4;
  /// Flush the file to disk after every frame (crash safety; costs throughput). When false a
  /// crash may lose every frame since the last Close().
  bool flush_each_frame = true;
  /// Identity of the calibration in effect while recording (e.g. a calibration file's name or
  /// hash); "" = none. Stored as the root attribute `calibration_id`.
  std::string calibration_id;

  /// Throws Error(kInvalidArgument) naming the field when out of range.
  void Validate() const;
};

/// Appends frames to a new recording. Not thread-safe.
class RecordingWriter {
 public:
  /// Creates (truncates) `path` and writes the camera description. Throws Error(kIo) when the
  /// file cannot be created, Error(kInvalidArgument) for invalid options or intrinsics.
  RecordingWriter(const std::filesystem::path& path, const CameraInfo& camera,
                  const RecordingOptions& options = {});
  /// Closes the file if still open; never throws (call Close() to see errors).
  ~RecordingWriter();
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  /// Appends one frame. The frame must match the camera's size (kMismatch otherwise), pass
  /// ValidateFrame (kInvalidArgument), and have source flags, confidence, ground truth and the
  /// truth's footprint iff the first frame had them (kMismatch); ground truth needs sigma_m
  /// (kMismatch). Its timestamp may not be before the previous frame's (kInvalidArgument: the
  /// reader would refuse the file; the frames appended before stay readable). Throws
  /// Error(kIo) on write failure and Error(kInvalidArgument) after Close().
  void Append(const Frame& frame);
  /// Flushes and closes; further Append() calls throw. Idempotent.
  void Close();

  /// Frames committed so far.
  [[nodiscard]] std::size_t frame_count() const noexcept;
  [[nodiscard]] const std::filesystem::path& path() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// What a recording says about itself.
struct RecordingMetadata {
  int format_version = 0;
  std::string tofcam_version;      ///< Version of the tofcam that wrote the file.
  CameraInfo camera;               ///< Camera description at the start of the recording.
  std::string calibration_id;      ///< "" = none.
  std::string frame_camera_model;  ///< FrameInfo::camera_model of every frame.
  bool has_source_flags = false;   ///< Frames carry source_flags.
  bool has_ground_truth = false;   ///< Frames carry GroundTruth.
  /// Their GroundTruth has footprint_near_m / _far_m (false for files written before those).
  bool has_truth_footprint = false;
  bool has_confidence = false;  ///< Frames carry the camera's confidence channel.
};

/// Random access to the frames of a recording. Opening reads and validates the metadata and the
/// per-frame info; Read() validates each frame's data. Not thread-safe (HDF5 handles).
class RecordingReader {
 public:
  /// Opens `path`. Throws Error(kNotFound) if missing, Error(kFormat) naming the problem when the
  /// file is not a valid recording (wrong types, hostile sizes, NaNs, missing datasets).
  explicit RecordingReader(const std::filesystem::path& path);
  ~RecordingReader();
  RecordingReader(RecordingReader&&) noexcept;
  RecordingReader& operator=(RecordingReader&&) noexcept;

  /// Number of complete frames (a frame in flight when the recorder died is not counted).
  [[nodiscard]] std::size_t frame_count() const noexcept;
  [[nodiscard]] const RecordingMetadata& metadata() const noexcept;
  [[nodiscard]] const std::filesystem::path& path() const noexcept;
  /// Frame `index` in [0, frame_count()), bit-identical to what was appended. Throws
  /// Error(kInvalidArgument) for an index out of range, Error(kFormat) for corrupted data.
  [[nodiscard]] Frame Read(std::size_t index) const;
  /// Per-frame info of frame `index` without reading the images (kInvalidArgument if out of
  /// range).
  [[nodiscard]] const FrameInfo& Info(std::size_t index) const;
  /// Index of the first frame whose timestamp is >= `timestamp_ns`; frame_count() if none.
  /// Timestamps are validated to be non-decreasing at open.
  [[nodiscard]] std::size_t IndexAtOrAfter(std::int64_t timestamp_ns) const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// How a PlaybackCamera serves frames.
struct PlaybackOptions {
  /// Throttle Grab() to the recorded timestamps (scaled by `speed`); false = as fast as possible.
  bool real_time = false;
  /// Real-time speed factor (> 0, finite): 2 plays twice as fast. Ignored unless real_time.
  double speed = 1.0;
  /// Start again at frame 0 after the last frame instead of ending. Each further pass continues
  /// the timestamps and sequence numbers of the one before (LoopContinuation).
  bool loop = false;

  /// Throws Error(kInvalidArgument) naming the field when out of range.
  void Validate() const;
};

/// Serves a recording as a Camera, frame-exactly: Grab() returns the recorded frames unchanged,
/// then std::nullopt (unless looping: then the first pass unchanged, the next ones with their
/// timestamps and sequence numbers continued).
///
/// Settings: a recording cannot change what was recorded, so SetIntegrationTimeRegister,
/// SetModulationFrequencyHz, SetDistanceOffsetRegister and SetPanAngleRad throw
/// Error(kUnsupported) unless the requested value equals the one recorded for the next frame
/// (then they are no-ops; this lets a controller that converged to the recorded value run).
/// The getters report the values of the next frame to be served.
class PlaybackCamera final : public Camera {
 public:
  /// Opens the recording (see RecordingReader for errors); throws kFormat for an empty one.
  explicit PlaybackCamera(const std::filesystem::path& path, const PlaybackOptions& options = {});

  [[nodiscard]] std::optional<Frame> Grab() override;
  [[nodiscard]] const CameraInfo& Info() const override { return info_; }

  void SetIntegrationTimeRegister(int reg) override;
  [[nodiscard]] int IntegrationTimeRegister() const override;
  void SetModulationFrequencyHz(double hz) override;
  void SetDistanceOffsetRegister(int reg) override;
  [[nodiscard]] int DistanceOffsetRegister() const override;
  void SetPanAngleRad(double angle_rad) override;
  [[nodiscard]] double PanAngleRad() const override;

  /// Makes frame `index` the next one Grab() returns (kInvalidArgument unless < frame_count()).
  /// In a looped playback the passes served so far keep counting: frames after a seek carry
  /// the current pass's continued timestamps.
  void Seek(std::size_t index);
  /// Seeks to the first frame with recorded timestamp >= `timestamp_ns` (kInvalidArgument if
  /// none): the times in the file, not the continued ones of a later pass.
  void SeekToTimeNs(std::int64_t timestamp_ns);
  /// Index of the next frame Grab() returns.
  [[nodiscard]] std::size_t position() const noexcept { return next_; }
  [[nodiscard]] std::size_t frame_count() const noexcept { return reader_.frame_count(); }
  [[nodiscard]] const RecordingReader& reader() const noexcept { return reader_; }

 private:
  [[nodiscard]] const FrameInfo& NextInfo() const;
  void RefreshInfo();

  RecordingReader reader_;
  PlaybackOptions options_;
  CameraInfo info_;
  std::size_t next_ = 0;
  // Real-time pacing: wall-clock time and recorded timestamp of the first frame after a (re)start.
  std::optional<std::chrono::steady_clock::time_point> start_wall_;
  std::int64_t start_timestamp_ns_ = 0;
  LoopContinuation loop_;  // what each further pass of a looped playback adds
};

}  // namespace tofcam

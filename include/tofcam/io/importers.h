#pragma once
/// \file
/// Importers for recordings of real ToF cameras (docs/importers.md). Each turns a camera's files
/// into tofcam Frames:
///  - distance register: radial distance over [0, L) with a per-camera L (below) chosen to cover
///    the camera's range; for millimetre cameras L is a power of two in mm so that the register
///    is an exact integer multiple of the millimetre value (lossless);
///  - amplitude register: the camera's amplitude / active-brightness / IR channel, clamped to
///    kMaxSignalRegister (values above it set Flag::kSaturated);
///  - intensity: zeros and FrameInfo::has_intensity = false (none of these cameras exports an
///    offset channel; the accuracy model then uses its amplitude-only form);
///  - source_flags: the camera's own invalid / saturated / low-amplitude markers (kInvalid,
///    kSaturated, kLowAmplitude); pixels without a distance are kInvalid with register 0.
///
/// Every importer validates sizes, types and ranges first; a missing file is Error(kNotFound), a
/// malformed, truncated or hostile one Error(kFormat) naming the file and the problem.

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tofcam/core/camera.h"
#include "tofcam/core/frame.h"

namespace tofcam {

/// Unambiguous range L (m) the importers use: ADI ADTF3175 and Azure Kinect 8.192 m (register =
/// 8 x mm), ifm O3D303 32.768 m (register = 2 x mm; its "up to 30 m" mode), MESA SR-4000 the
/// camera's own 30 MHz (L = 4.9965 m).
inline constexpr double kImportRangeAdiM = 8.192;
inline constexpr double kImportRangeAzureKinectM = 8.192;
inline constexpr double kImportRangeIfmM = 32.768;
inline constexpr double kMesaModulationFrequencyHz = 30e6;

/// A camera description plus all frames of an imported file.
struct ImportedSequence {
  CameraInfo camera;
  std::vector<Frame> frames;
  /// Noise scale of this camera's ΔL (AccuracyOptions::scale, σ = scale x ΔL of eq. 2 with
  /// scale 1, amplitude-only form) where the importer knows it; see docs/importers.md. The ΔL of
  /// an imported camera is in its own register convention (L, amplitude units), so without a
  /// scale the paper's threshold in metres means nothing for it.
  std::optional<double> delta_l_scale;
  std::string delta_l_scale_note;  ///< Where delta_l_scale came from, one line.
};

/// The noise scale a static multi-frame recording gives itself: FitDeltaLScale over its frames
/// (all at one integration time; the temporal σ of each pixel against its ΔL). nullopt with
/// fewer than 3 frames, frames of different sizes, or too few pixels valid in every frame. A
/// scene that moved inflates σ and so the scale: the accuracy filter then rejects more (fails
/// safe). Uses the first frames up to 2^22 pixels in all (at least three), so that a long
/// sequence does not need its metric copies all at once. Used by the importers of multi-frame
/// formats.
[[nodiscard]] std::optional<double> SelfCalibratedNoiseScale(const std::vector<Frame>& frames);

/// ifm O3D303 HDF5 as written by libo3d3xx (`/o3d3xx/camera/<stream>/<N>`): streams depth (mm,
/// radial, 0 = invalid), raw_amplitude, confidence (bit0 invalid -> kInvalid, bit1 saturated ->
/// kSaturated, bit2 bad symmetry -> kInvalid, bit3 low amplitude -> kLowAmplitude) and xyz (used
/// to fit the pinhole intrinsics). Frames are ordered by their `seq` attribute; timestamps come
/// from `stamp.secs`/`stamp.nsecs`, relative to the first frame.
/// delta_l_scale: SelfCalibratedNoiseScale of the file's frames (libo3d3xx dumps of a camera
/// standing still; the ifm stores no noise figure).
[[nodiscard]] ImportedSequence ImportIfmO3d3xx(const std::filesystem::path& h5_file);

/// ADI ADTF3175 interleaved frame (no header, 5 bytes per pixel: depth uint16 LE in mm,
/// confidence uint8, active brightness uint16 LE). The file must hold exactly width x height x 5
/// bytes. Depth 0 -> kInvalid.
[[nodiscard]] ImportedSequence ImportAdiInterleaved(const std::filesystem::path& bin_file,
                                                    int width = 512, int height = 512);
/// Same from memory; `name` names the source in errors (used by the fuzzer).
[[nodiscard]] ImportedSequence ParseAdiInterleaved(std::string_view bytes, int width, int height,
                                                   const std::string& name);

/// ADI raw depth + IR files (uint16 LE, no header, width x height each; depth in mm).
[[nodiscard]] ImportedSequence ImportAdiRaw(const std::filesystem::path& depth_file,
                                            const std::filesystem::path& ir_file, int width = 512,
                                            int height = 512);

/// Azure Kinect raw depth (uint16 LE, mm along the optical axis z, 0 = invalid) and IR (uint16 LE,
/// 65535 = saturated -> kSaturated) with the factory calibration.json. The depth mode follows
/// from the image size (640x576 NFOV unbinned, 320x288 NFOV binned, 512x512 WFOV binned,
/// 1024x1024 WFOV unbinned). z is converted to radial distance along each pixel's ray.
[[nodiscard]] ImportedSequence ImportAzureKinect(const std::filesystem::path& depth_file,
                                                 const std::filesystem::path& ir_file,
                                                 const std::filesystem::path& calibration_json,
                                                 int width = 640, int height = 576);
/// The depth camera's intrinsics in a depth mode of `width` x `height` from the calibration JSON
/// (Brown-Conrady parameters cx, cy, fx, fy normalised by the 1024 x 1024 sensor; k1..k6; codx,
/// cody (must be 0); p2, p1), converted to pixel units of the cropped/binned mode image with
/// tofcam's pixel-centre convention. Throws kFormat naming the problem.
[[nodiscard]] CameraIntrinsics ParseAzureKinectCalibration(std::string_view json, int width,
                                                           int height, const std::string& name);

/// MESA SwissRanger sample-viewer text export (`.dat`, docs/importers.md). Each file holds one
/// frame (several in a row are accepted): sections headed by '%' lines, recognised by their
/// words: `% Calibrated Distance` (z, m), `% Calibrated xVector` (x, m), `% Calibrated yVector`
/// (y, m), `% Amplitude`, `% Confidence map` (optional) — each `height` rows of `width`
/// tab-separated numbers — and `% additional data / time stamp [ms]`, whose one row starts with
/// the time stamp (then nan padding; the older "% timestamp [ms]: 1234" header form is read too).
/// Other '%' sections are skipped. Radial distance = sqrt(x^2 + y^2 + z^2); a non-finite or
/// non-positive z, a non-finite x/y or confidence 0 -> kInvalid. The confidence map is kept as
/// Frame::confidence. Intrinsics are fitted to the x/z and y/z of the first frame's valid pixels
/// (nominal SR-4000 values when fewer than 16 are valid). `path` is a file, a folder (every
/// `.dat` in it) or a file-name glob (`rec/frm_*.dat`); files are taken in natural order
/// (frm_2 before frm_10) and time stamps are relative to the first frame of the first file.
[[nodiscard]] ImportedSequence ImportMesaDat(const std::filesystem::path& path);
/// One export from memory; `name` names the source in errors.
[[nodiscard]] ImportedSequence ParseMesaDat(std::string_view text, const std::string& name);

/// The files of a sequence: `path` itself when it is a file, the files ending in `extension`
/// in it when it is a folder, or the files whose names match a glob ('*', '?') in the file-name
/// part; sorted in natural order. Throws Error(kNotFound) when nothing matches.
[[nodiscard]] std::vector<std::filesystem::path> ExpandSequencePath(
    const std::filesystem::path& path, const std::string& extension);

/// Imports by CLI spec "<format>:<path>": `ifm-o3d3xx:<file.h5>`, `adi-interleaved:<file.bin>`,
/// `adi-raw:<depth.bin>[,<ir.bin>]` (default IR file: "depth" replaced by "ir" in the name),
/// `azure-kinect:<dir>` (depth_<W>x<H>_u16le.bin, ir_<W>x<H>_u16le.bin, calibration.json, W x H
/// one of the four depth modes) or `azure-kinect:<depth.bin>,<ir.bin>,<calibration.json>` (the
/// mode from the depth file's size), `mesa-dat:<file.dat | folder | glob>`.
/// Unknown formats are kInvalidArgument listing the known ones.
[[nodiscard]] ImportedSequence ImportFromSpec(const std::string& spec);

/// Names of the formats ImportFromSpec accepts.
[[nodiscard]] std::vector<std::string> ImportFormats();

/// Serves an imported sequence as a Camera: Grab() returns the frames in order, then
/// std::nullopt (or starts again when `loop`, continuing the timestamps and sequence numbers:
/// LoopContinuation). Like PlaybackCamera, setters throw
/// Error(kUnsupported) unless the value equals the one of the next frame.
class ImportedCamera final : public Camera {
 public:
  /// Throws Error(kFormat) when the sequence has no frames.
  explicit ImportedCamera(ImportedSequence sequence, bool loop = false);

  [[nodiscard]] std::optional<Frame> Grab() override;
  [[nodiscard]] const CameraInfo& Info() const override { return sequence_.camera; }
  void SetIntegrationTimeRegister(int reg) override;
  [[nodiscard]] int IntegrationTimeRegister() const override;
  void SetModulationFrequencyHz(double hz) override;
  void SetDistanceOffsetRegister(int reg) override;
  [[nodiscard]] int DistanceOffsetRegister() const override;
  void SetPanAngleRad(double angle_rad) override;
  [[nodiscard]] double PanAngleRad() const override;

  [[nodiscard]] std::size_t frame_count() const noexcept { return sequence_.frames.size(); }
  /// The sequence's noise scale (ImportedSequence::delta_l_scale) and where it came from.
  [[nodiscard]] std::optional<double> delta_l_scale() const noexcept {
    return sequence_.delta_l_scale;
  }
  [[nodiscard]] const std::string& delta_l_scale_note() const noexcept {
    return sequence_.delta_l_scale_note;
  }

 private:
  [[nodiscard]] const FrameInfo& NextInfo() const;

  ImportedSequence sequence_;
  bool loop_;
  LoopContinuation continuation_;  // what each further pass of a looped sequence adds
  std::size_t next_ = 0;
};

}  // namespace tofcam

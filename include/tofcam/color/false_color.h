#pragma once
/// \file
/// The paper's false-colour display (section III-A): HSV with hue 60° (yellow) at the near limit
/// running backwards through red (0°) and magenta (300°) to 240° (blue) at the far limit, over
/// a fixed distance range (never histogram-equalised). Plus a legend bar with tick labels.

#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/pixel_flags.h"
#include "tofcam/core/rgb.h"

namespace tofcam {

/// Colour law. With t = (d - near_m) / (far_m - near_m) the hue is 60° - t·180° (mod 360°),
/// saturation 1, value V; each channel is round(255 · channel) of the HSV→RGB conversion.
/// Along this hue path the conversion is exactly R = clamp(3 - 3t), G = clamp(1 - 3t),
/// B = clamp(3t - 1) (clamped to [0, 1]), times V, which is how it is computed.
struct FalseColorOptions {
  double near_m = 0.0;  ///< Distance shown yellow, m; >= 0.
  /// Distance shown blue, m; > near_m, or 0 = the frame's unambiguous range L.
  double far_m = 0.0;
  /// False: distances outside [near_m, far_m] take the colour of the nearer limit.
  /// True: they are drawn black like rejected pixels.
  bool out_of_range_black = false;
  /// Amplitude shading: V = shading_min_value + (1 - shading_min_value) ·
  /// min(1, sqrt(amplitude / shading_reference_amplitude)); V = 1 when off. The square root
  /// undoes the 1/d² fall-off of the amplitude to first order (brightness ~ 1/d), so near and
  /// far surfaces of the same albedo look alike and dark (noisy) ones look dark. NaN or
  /// negative amplitude gives shading_min_value.
  bool amplitude_shading = false;
  double shading_reference_amplitude = 8000.0;  ///< Amplitude at full brightness, registers; > 0.
  double shading_min_value = 0.25;              ///< Darkest V, [0, 1].
  void Validate() const;
};

/// False colour of a frame: pixels with a kRejectMask bit or a non-finite distance are black
/// (0, 0, 0). far_m = 0 uses L from `frame.info.modulation_frequency_hz`. Throws
/// Error(kInvalidArgument) for an empty frame, inconsistent sizes, shading without an
/// amplitude image, or far_m <= near_m after resolving far_m.
[[nodiscard]] Image<Rgb8> FalseColor(const MetricFrame& frame, const FalseColorOptions& options);

/// The same law for a bare distance image (e.g. the panorama). `flags` and `amplitude` may be
/// empty (no rejects / no shading); `far_default_m` (> 0) replaces far_m = 0.
[[nodiscard]] Image<Rgb8> FalseColorImage(const Image<float>& distance_m,
                                          const Image<PixelFlags>& flags,
                                          const Image<float>& amplitude, double far_default_m,
                                          const FalseColorOptions& options);

/// The same into `out`, reusing its storage when it already has the distance image's size (a
/// per-frame loop allocates nothing); every pixel is overwritten. Throws like FalseColorImage,
/// before anything is written.
void FalseColorImageInto(const Image<float>& distance_m, const Image<PixelFlags>& flags,
                         const Image<float>& amplitude, double far_default_m,
                         const FalseColorOptions& options, Image<Rgb8>& out);

/// Colour of one distance (V = 1), t clamped to [0, 1]; for legends and tests.
[[nodiscard]] Rgb8 FalseColorOfDistance(double distance_m, double near_m, double far_m);

struct LegendOptions {
  int bar_height_px = 8;  ///< Height of the colour bar, px; [2, 256].
  int font_scale = 1;     ///< Integer magnification of the built-in 3x5 font; [1, 8].
  void Validate() const;
};

/// `image` with a legend strip appended below it: a colour bar from near_m (left, yellow) to
/// far_m (right, blue) over the image width, white tick marks at round distances (steps of 1, 2
/// or 5 × 10^k m, as dense as the labels allow) and their values in metres in a built-in 3x5
/// pixel font. Throws Error(kInvalidArgument) for an image narrower than 16 px, or when
/// far_m <= near_m or either is not finite.
[[nodiscard]] Image<Rgb8> AddLegend(const Image<Rgb8>& image, double near_m, double far_m,
                                    const LegendOptions& options = {});

}  // namespace tofcam

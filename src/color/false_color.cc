#include "tofcam/color/false_color.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "../core/avx512_forms.h"
#include "../filters/hot_loop.h"
#include "../filters/simd.h"
#include "false_color_internal.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

#if defined(TOFCAM_AVX512_FORMS)
#include <immintrin.h>
#endif

namespace tofcam {
namespace {

constexpr float kMaxF = std::numeric_limits<float>::max();
constexpr std::int32_t kInfBits = 0x7f800000;  // the bit pattern of +inf

std::uint8_t ToByte(float v) {  // v in [0, 1]; round half up
  return static_cast<std::uint8_t>(static_cast<int>(v * 255.0f + 0.5f));
}

void CheckSize(const Image<float>& d, int w, int h, const char* what) {
  if (!d.empty() && !d.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument,
                std::string("false colour: ") + what + " differs in size from the distance image");
  }
}

// 3x5 glyphs, one row per entry, bit 2 = left column.
struct Glyph {
  char c;
  std::array<std::uint8_t, 5> rows;
};
constexpr Glyph kFont[] = {
    {'0', {7, 5, 5, 5, 7}}, {'1', {2, 6, 2, 2, 7}}, {'2', {7, 1, 7, 4, 7}}, {'3', {7, 1, 7, 1, 7}},
    {'4', {5, 5, 7, 1, 1}}, {'5', {7, 4, 7, 1, 7}}, {'6', {7, 4, 7, 5, 7}}, {'7', {7, 1, 1, 2, 2}},
    {'8', {7, 5, 7, 5, 7}}, {'9', {7, 5, 7, 1, 7}}, {'.', {0, 0, 0, 0, 2}}, {'-', {0, 0, 7, 0, 0}},
    {'m', {0, 0, 7, 7, 5}},
};

const std::array<std::uint8_t, 5>* FindGlyph(char c) {
  for (const Glyph& g : kFont) {
    if (g.c == c) return &g.rows;
  }
  return nullptr;
}

void DrawText(Image<Rgb8>& img, int x0, int y0, const std::string& text, int scale, Rgb8 color) {
  for (std::size_t k = 0; k < text.size(); ++k) {
    const auto* g = FindGlyph(text[k]);
    if (g == nullptr) continue;
    for (int gy = 0; gy < 5; ++gy) {
      for (int gx = 0; gx < 3; ++gx) {
        if (((*g)[gy] >> (2 - gx) & 1) == 0) continue;
        for (int sy = 0; sy < scale; ++sy) {
          for (int sx = 0; sx < scale; ++sx) {
            const int x = x0 + (static_cast<int>(k) * 4 + gx) * scale + sx;
            const int y = y0 + gy * scale + sy;
            if (x >= 0 && y >= 0 && x < img.width() && y < img.height()) img(y, x) = color;
          }
        }
      }
    }
  }
}

struct ColorLaw {
  float near, inv_range, v_min, inv_ref;
  bool black_outside, shade;
};

// One row into interleaved RGB bytes (`rgb`, 3 per pixel); the caller passes zero-filled rows
// for missing flags / amplitude. Written with vector extensions, eight pixels per step: GCC's own
// vectorisation of the scalar form unrolled to 32 pixels with the float to byte conversions
// spilled to the stack (about 7 cycles per pixel). Every operation is the scalar law's, in its
// order: std::max(x, 0) is (x < 0 ? 0 : x) and std::min(x, 1) is (1 < x ? 1 : x), including for
// NaN. Without shading v is exactly the visibility (the law's 1 + 0·(s - 1) is 1 for every
// finite s), so the square root is skipped, and the law's bytes are those of v = 1 masked by
// visibility (255·v·x + 0.5 truncates to 0 when v = 0); and since t lies in [0, 1] there,
// 3 - 3t >= 0 and 1 - 3t <= 1 exactly, so those two clamps reduce to their other side.
template <bool kShade>
[[gnu::always_inline]] inline void ColorRowBody(int w, const ColorLaw& law,
                                                const float* __restrict d,
                                                const PixelFlags* __restrict f,
                                                const float* __restrict a,
                                                std::uint8_t* __restrict rgb) {
  using namespace simd;
  const float near = law.near, inv_range = law.inv_range, v_min = law.v_min;
  const float inv_ref = law.inv_ref;
  const F8 zero = {}, one = zero + 1.0f;
  auto clamp01 = [&](F8 x) {
    x = x < zero ? zero : x;
    return one < x ? one : x;
  };
  typedef std::uint8_t B32 __attribute__((vector_size(32)));
  typedef std::uint8_t B16 __attribute__((vector_size(16)));
  typedef std::uint8_t B8 __attribute__((vector_size(8)));
  // Three int32 vectors of values in [0, 255] (r, g, b of 8 pixels) into 24 bytes r0 g0 b0 r1
  // ... b7 at `dst`: each pixel's bytes packed into one lane, then the lanes' low three bytes
  // gathered by one byte shuffle, stored as 16 + 8 bytes (no store past the 24).
  auto store_rgb = [](I8 r, I8 g, I8 b, I8 mask, std::uint8_t* dst) {
    const B32 packed = reinterpret_cast<B32>((r | (g << 8) | (b << 16)) & mask);
    const B32 bytes =
        __builtin_shufflevector(packed, packed, 0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, 16, 17, 18,
                                20, 21, 22, 24, 25, 26, 28, 29, 30, 0, 0, 0, 0, 0, 0, 0, 0);
    const B16 lo =
        __builtin_shufflevector(bytes, bytes, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const B8 hi = __builtin_shufflevector(bytes, bytes, 16, 17, 18, 19, 20, 21, 22, 23);
    std::memcpy(dst, &lo, 16);
    std::memcpy(dst + 16, &hi, 8);
  };
  int i = 0;
  for (; i + 8 <= w; i += 8) {
    const F8 dv = LoadF8(d + i);
    const F8 t_raw = (dv - near) * inv_range;
    // |d| <= max float, i.e. its bits below those of +inf (bit patterns of non-negative floats
    // order as integers; NaN and inf lie above): false for NaN and ±inf. Written as a strict
    // "greater than", the one integer compare AVX2 has.
    I8 visible = (kInfBits > AbsBits(dv)) & ((LoadFlags8(f + i) & kRejectMask) == 0);
    if (law.black_outside) visible &= (t_raw >= 0.0f) & (t_raw <= 1.0f);
    // Invisible pixels get t = 0 (their bytes are 0 whatever t is; NaN t would convert to an
    // unspecified integer).
    const F8 t = Select(visible, clamp01(t_raw));
    I8 rv, gv, bv;
    if constexpr (kShade) {
      F8 v = Select(visible, one);
      F8 ai = LoadF8(a + i);
      ai = ai >= 0.0f ? ai : zero;  // NaN -> 0
      F8 root = ai * inv_ref;
      for (int k = 0; k < 8; ++k) root[k] = std::sqrt(root[k]);
      const F8 m = root < one ? root : one;  // std::min(1, x) = (x < 1 ? x : 1)
      const F8 shading = v_min + (1.0f - v_min) * m;
      v = v * (1.0f + (shading - 1.0f));
      const F8 scale = 255.0f * v;
      rv = __builtin_convertvector(scale * clamp01(3.0f - 3.0f * t) + 0.5f, I8);
      gv = __builtin_convertvector(scale * clamp01(1.0f - 3.0f * t) + 0.5f, I8);
      bv = __builtin_convertvector(scale * clamp01(3.0f * t - 1.0f) + 0.5f, I8);
    } else {
      // The visibility mask is applied once to the packed bytes (store_rgb).
      const F8 x_r = 3.0f - 3.0f * t, x_g = 1.0f - 3.0f * t;
      rv = __builtin_convertvector(255.0f * (one < x_r ? one : x_r) + 0.5f, I8);
      gv = __builtin_convertvector(255.0f * (x_g < zero ? zero : x_g) + 0.5f, I8);
      bv = __builtin_convertvector(255.0f * clamp01(3.0f * t - 1.0f) + 0.5f, I8);
    }
    // Shaded: v is 0 for invisible pixels already, so the mask changes nothing there.
    store_rgb(rv, gv, bv, visible, rgb + 3 * i);
  }
  const unsigned outside = law.black_outside ? 0u : 1u;
  for (; i < w; ++i) {
    const float t_raw = (d[i] - near) * inv_range;
    const unsigned in_range =
        static_cast<unsigned>(t_raw >= 0.0f) & static_cast<unsigned>(t_raw <= 1.0f);
    const bool visible =
        (static_cast<unsigned>(std::abs(d[i]) <= kMaxF) &
         static_cast<unsigned>((f[i].bits() & kRejectMask) == 0) & (in_range | outside)) != 0;
    const float t = visible ? std::min(std::max(t_raw, 0.0f), 1.0f) : 0.0f;
    float v = visible ? 1.0f : 0.0f;
    if constexpr (kShade) {
      const float ai = a[i] >= 0.0f ? a[i] : 0.0f;
      const float shading = v_min + (1.0f - v_min) * std::min(1.0f, std::sqrt(ai * inv_ref));
      v = v * (1.0f + (shading - 1.0f));
    }
    const float scale = 255.0f * v;
    rgb[3 * i] = static_cast<std::uint8_t>(
        static_cast<int>(scale * std::min(std::max(3.0f - 3.0f * t, 0.0f), 1.0f) + 0.5f));
    rgb[3 * i + 1] = static_cast<std::uint8_t>(
        static_cast<int>(scale * std::min(std::max(1.0f - 3.0f * t, 0.0f), 1.0f) + 0.5f));
    rgb[3 * i + 2] = static_cast<std::uint8_t>(
        static_cast<int>(scale * std::min(std::max(3.0f * t - 1.0f, 0.0f), 1.0f) + 0.5f));
  }
}

TOFCAM_HOT_LOOP void ColorRowPlain(int w, const ColorLaw& law, const float* __restrict d,
                                   const PixelFlags* __restrict f, const float* __restrict a,
                                   std::uint8_t* __restrict rgb) {
  ColorRowBody<false>(w, law, d, f, a, rgb);
}

TOFCAM_HOT_LOOP void ColorRowShaded(int w, const ColorLaw& law, const float* __restrict d,
                                    const PixelFlags* __restrict f, const float* __restrict a,
                                    std::uint8_t* __restrict rgb) {
  ColorRowBody<true>(w, law, d, f, a, rgb);
}

#if defined(TOFCAM_AVX512_FORMS)
// ColorRowBody for AVX-512 CPUs, sixteen pixels at a time, written with intrinsics: the generic
// 8-lane form spends two instructions (compare, blend) on each clamp and four on moving 24 bytes
// out of a 32-byte vector (about 3 cycles per pixel on the Zen 4 test machine). The same values
// bit for bit: every clamp here has a finite operand where the mask keeps it, and there
// std::max(x, 0) = (x < 0 ? 0 : x) = vmaxps(x, 0) and std::min(x, 1) = (1 < x ? 1 : x) =
// vminps(x, 1) up to the sign of a zero, which the multiply by 255, the + 0.5 and the truncation
// remove. t is never NaN on a visible pixel (finite d and a finite inv_range, which
// FalseColorImageInto checks), ±inf there clamps to 0 or 1 in both forms, and a NaN t of an
// invisible pixel becomes 0 in vmaxps while the visibility mask zeroes its bytes. Separate
// multiplies and adds in the law's order (the file is built with -ffp-contract=off). The last
// block's loads and its store are masked: nothing is read or written past the row.
TOFCAM_AVX512_DIAGNOSTICS_BEGIN

template <bool kShade>
TOFCAM_AVX512_INLINE void ColorRow16Body(int w, const ColorLaw& law, const float* __restrict d,
                                         const PixelFlags* __restrict f, const float* __restrict a,
                                         std::uint8_t* __restrict rgb) {
  const __m512 near = _mm512_set1_ps(law.near), inv_range = _mm512_set1_ps(law.inv_range);
  const __m512 zero = _mm512_setzero_ps(), one = _mm512_set1_ps(1.0f);
  const __m512 three = _mm512_set1_ps(3.0f), c255 = _mm512_set1_ps(255.0f);
  const __m512 half = _mm512_set1_ps(0.5f);
  const __m512 inf = _mm512_set1_ps(std::numeric_limits<float>::infinity());
  const __m512 v_min = _mm512_set1_ps(law.v_min), span = _mm512_set1_ps(1.0f - law.v_min);
  const __m512 inv_ref = _mm512_set1_ps(law.inv_ref);
  const __m256i reject = _mm256_set1_epi16(static_cast<short>(kRejectMask));
  // Per 128-bit lane: the low three bytes of each of its four pixels' 32-bit words, packed into
  // the lane's first 12 bytes; then the four 12-byte groups side by side (48 bytes).
  const __m512i bytes_in_lane =
      _mm512_broadcast_i32x4(_mm_setr_epi8(0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1));
  const __m512i lanes = _mm512_setr_epi32(0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, 0, 0, 0, 0);
  const bool black_outside = law.black_outside;
  for (int i = 0; i < w; i += 16) {
    const int left = w - i;
    const __mmask16 in = left >= 16 ? __mmask16{0xFFFF} : static_cast<__mmask16>((1u << left) - 1u);
    const __m512 dv = _mm512_maskz_loadu_ps(in, d + i);
    const __m512 t_raw = _mm512_mul_ps(_mm512_sub_ps(dv, near), inv_range);
    // |d| < inf: false for NaN and ±inf; no reject flag.
    __mmask16 visible = in & _mm512_cmp_ps_mask(_mm512_abs_ps(dv), inf, _CMP_LT_OQ) &
                        _mm256_testn_epi16_mask(_mm256_maskz_loadu_epi16(in, f + i), reject);
    if (black_outside) {
      visible &=
          _mm512_cmp_ps_mask(t_raw, zero, _CMP_GE_OQ) & _mm512_cmp_ps_mask(t_raw, one, _CMP_LE_OQ);
    }
    const __m512 t = _mm512_min_ps(_mm512_max_ps(t_raw, zero), one);
    const __m512 t3 = _mm512_mul_ps(three, t);
    __m512 r = _mm512_sub_ps(three, t3);                     // >= 0 for t in [0, 1]
    __m512 g = _mm512_max_ps(_mm512_sub_ps(one, t3), zero);  // <= 1 for t in [0, 1]
    __m512 b = _mm512_min_ps(_mm512_max_ps(_mm512_sub_ps(t3, one), zero), one);
    r = _mm512_min_ps(r, one);
    __m512 scale = c255;
    if constexpr (kShade) {
      __m512 ai = _mm512_maskz_loadu_ps(in, a + i);
      ai = _mm512_max_ps(ai, zero);  // NaN -> 0
      const __m512 m = _mm512_min_ps(_mm512_sqrt_ps(_mm512_mul_ps(ai, inv_ref)), one);
      const __m512 shading = _mm512_add_ps(v_min, _mm512_mul_ps(span, m));
      // The law's v * (1 + (shading - 1)) with v = 1 on visible pixels.
      scale = _mm512_mul_ps(c255, _mm512_add_ps(one, _mm512_sub_ps(shading, one)));
    }
    const __m512i rv = _mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(scale, r), half));
    const __m512i gv = _mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(scale, g), half));
    const __m512i bv = _mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(scale, b), half));
    // r | g << 8 | b << 16 in visible pixels, 0 elsewhere.
    const __m512i packed = _mm512_maskz_ternarylogic_epi32(visible, rv, _mm512_slli_epi32(gv, 8),
                                                           _mm512_slli_epi32(bv, 16), 0xFE);
    const __m512i out = _mm512_permutexvar_epi32(lanes, _mm512_shuffle_epi8(packed, bytes_in_lane));
    const __mmask64 bytes =
        left >= 16 ? __mmask64{0xFFFFFFFFFFFFull} : (__mmask64{1} << (3 * left)) - 1u;
    _mm512_mask_storeu_epi8(rgb + 3 * static_cast<std::ptrdiff_t>(i), bytes, out);
  }
}

TOFCAM_AVX512_TARGET void ColorRow16(int w, const ColorLaw& law, const float* __restrict d,
                                     const PixelFlags* __restrict f, const float* __restrict a,
                                     std::uint8_t* __restrict rgb) {
  if (law.shade) {
    ColorRow16Body<true>(w, law, d, f, a, rgb);
  } else {
    ColorRow16Body<false>(w, law, d, f, a, rgb);
  }
}

TOFCAM_AVX512_DIAGNOSTICS_END

#endif

void ColorRow(int w, const ColorLaw& law, const float* d, const PixelFlags* f, const float* a,
              std::uint8_t* rgb) {
#if defined(TOFCAM_AVX512_FORMS)
  if (internal::UseAvx512Forms()) {
    ColorRow16(w, law, d, f, a, rgb);
    return;
  }
#endif
  if (law.shade) {
    ColorRowShaded(w, law, d, f, a, rgb);
  } else {
    ColorRowPlain(w, law, d, f, a, rgb);
  }
}

// The law's single-precision constants; throws Error(kInvalidArgument) when the far limit is not
// finite and beyond near_m, or so close to it that 1 / (far - near) overflows a float (then
// (d - near) * inv_range would be NaN at d = near).
ColorLaw MakeLaw(const FalseColorOptions& o, double far) {
  if (!(std::isfinite(far) && far > o.near_m)) {
    throw Error(ErrorCode::kInvalidArgument,
                "false colour: far limit " + std::to_string(far) +
                    " m must exceed near_m = " + std::to_string(o.near_m) + " m");
  }
  const float inv_range = static_cast<float>(1.0 / (far - o.near_m));
  if (!std::isfinite(inv_range)) {
    throw Error(ErrorCode::kInvalidArgument,
                "false colour: far limit " + std::to_string(far) +
                    " m is too close to near_m = " + std::to_string(o.near_m) + " m");
  }
  return ColorLaw{static_cast<float>(o.near_m),
                  inv_range,
                  static_cast<float>(o.shading_min_value),
                  static_cast<float>(1.0 / o.shading_reference_amplitude),
                  o.out_of_range_black,
                  o.amplitude_shading};
}

}  // namespace

namespace color_internal {

void ColorRowForTesting(int w, const FalseColorOptions& o, double far_m, const float* d,
                        const PixelFlags* flags, const float* amplitude, std::uint8_t* rgb) {
  o.Validate();
  ColorRow(w, MakeLaw(o, far_m), d, flags, amplitude, rgb);
}

}  // namespace color_internal

void FalseColorOptions::Validate() const {
  if (!(near_m >= 0.0 && near_m < 1e6)) {
    throw Error(ErrorCode::kInvalidArgument,
                "false colour: near_m = " + std::to_string(near_m) + " must be in [0, 1e6) m");
  }
  if (!(far_m == 0.0 || (far_m > near_m && far_m <= 1e6))) {
    throw Error(ErrorCode::kInvalidArgument, "false colour: far_m = " + std::to_string(far_m) +
                                                 " must be 0 (= L) or in (near_m, 1e6] m");
  }
  if (!(shading_reference_amplitude > 0.0 && shading_reference_amplitude <= 1e9)) {
    throw Error(ErrorCode::kInvalidArgument, "false colour: shading_reference_amplitude = " +
                                                 std::to_string(shading_reference_amplitude) +
                                                 " must be > 0");
  }
  if (!(shading_min_value >= 0.0 && shading_min_value <= 1.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "false colour: shading_min_value = " + std::to_string(shading_min_value) +
                    " is outside [0, 1]");
  }
}

Rgb8 FalseColorOfDistance(double distance_m, double near_m, double far_m) {
  const float t =
      std::clamp(static_cast<float>((distance_m - near_m) / (far_m - near_m)), 0.0f, 1.0f);
  return {ToByte(std::clamp(3.0f - 3.0f * t, 0.0f, 1.0f)),
          ToByte(std::clamp(1.0f - 3.0f * t, 0.0f, 1.0f)),
          ToByte(std::clamp(3.0f * t - 1.0f, 0.0f, 1.0f))};
}

Image<Rgb8> FalseColorImage(const Image<float>& distance_m, const Image<PixelFlags>& flags,
                            const Image<float>& amplitude, double far_default_m,
                            const FalseColorOptions& o) {
  Image<Rgb8> out;
  FalseColorImageInto(distance_m, flags, amplitude, far_default_m, o, out);
  return out;
}

void FalseColorImageInto(const Image<float>& distance_m, const Image<PixelFlags>& flags,
                         const Image<float>& amplitude, double far_default_m,
                         const FalseColorOptions& o, Image<Rgb8>& out) {
  o.Validate();
  const int w = distance_m.width(), h = distance_m.height();
  if (distance_m.empty()) {
    throw Error(ErrorCode::kInvalidArgument, "false colour: empty distance image");
  }
  CheckSize(amplitude, w, h, "amplitude");
  if (!flags.empty() && !flags.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument,
                "false colour: flags differ in size from the distance image");
  }
  if (o.amplitude_shading && amplitude.empty()) {
    throw Error(ErrorCode::kInvalidArgument,
                "false colour: amplitude shading needs an amplitude image");
  }
  const ColorLaw law = MakeLaw(o, o.far_m > 0.0 ? o.far_m : far_default_m);
  if (!out.SameSize(w, h)) out = Image<Rgb8>(w, h);
  thread_local std::vector<float> zero_amplitude;
  thread_local std::vector<PixelFlags> zero_flags;
  zero_amplitude.assign(static_cast<std::size_t>(w), 0.0f);
  zero_flags.assign(static_cast<std::size_t>(w), PixelFlags());
  static_assert(sizeof(Rgb8) == 3);
  for (int row = 0; row < h; ++row) {
    // Every form writes exactly the row's 3 w bytes (no padding written).
    ColorRow(w, law, distance_m.Row(row).data(),
             flags.empty() ? zero_flags.data() : flags.Row(row).data(),
             amplitude.empty() ? zero_amplitude.data() : amplitude.Row(row).data(),
             reinterpret_cast<std::uint8_t*>(out.Row(row).data()));
  }
}

Image<Rgb8> FalseColor(const MetricFrame& frame, const FalseColorOptions& options) {
  const double f = frame.info.modulation_frequency_hz;
  if (!(std::isfinite(f) && f > 0.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "false colour: frame modulation frequency must be > 0");
  }
  return FalseColorImage(frame.radial_distance_m, frame.flags, frame.amplitude,
                         UnambiguousRangeM(f), options);
}

void LegendOptions::Validate() const {
  if (bar_height_px < 2 || bar_height_px > 256) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "legend: bar_height_px = " + std::to_string(bar_height_px) + " is outside [2, 256]");
  }
  if (font_scale < 1 || font_scale > 8) {
    throw Error(ErrorCode::kInvalidArgument,
                "legend: font_scale = " + std::to_string(font_scale) + " is outside [1, 8]");
  }
}

Image<Rgb8> AddLegend(const Image<Rgb8>& image, double near_m, double far_m,
                      const LegendOptions& o) {
  o.Validate();
  if (image.width() < 16 || image.height() < 1) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "legend: image of width " + std::to_string(image.width()) + " is narrower than 16 px");
  }
  if (!(std::isfinite(near_m) && std::isfinite(far_m) && far_m > near_m)) {
    throw Error(ErrorCode::kInvalidArgument, "legend: far_m = " + std::to_string(far_m) +
                                                 " must exceed near_m = " + std::to_string(near_m));
  }
  const int w = image.width();
  const int s = o.font_scale;
  const int margin = 2 * s;
  const int tick_len = 2 * s;
  const int text_h = 5 * s;
  const int bar_top = image.height() + margin;
  const int tick_top = bar_top + o.bar_height_px;
  const int text_top = tick_top + tick_len + s;
  const int total_h = text_top + text_h + margin;
  Image<Rgb8> out(w, total_h);
  for (int r = 0; r < image.height(); ++r) {
    std::copy(image.Row(r).begin(), image.Row(r).end(), out.Row(r).begin());
  }
  // The bar spans pixel centres left..right; pixel x shows distance near + (x-left)/(right-left).
  const int left = margin, right = w - 1 - margin;
  for (int x = left; x <= right; ++x) {
    const Rgb8 c = FalseColorOfDistance(near_m + (far_m - near_m) * (x - left) / (right - left),
                                        near_m, far_m);
    for (int y = bar_top; y < tick_top; ++y) out(y, x) = c;
  }

  // Tick step: the smallest 1/2/5 × 10^k whose labels (plus a gap) fit between ticks.
  const double px_per_m = (right - left) / (far_m - near_m);
  double step = 0.0;
  int decimals = 0;
  for (int e = -3; e <= 6 && step == 0.0; ++e) {
    for (double m : {1.0, 2.0, 5.0}) {
      const double cand = m * std::pow(10.0, e);
      const int dec = std::max(0, -e);
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.*f", dec, std::max(std::abs(near_m), std::abs(far_m)));
      const double label_px = (4.0 * static_cast<double>(std::string(buf).size()) + 2.0) * s;
      if (cand * px_per_m >= label_px) {
        step = cand;
        decimals = dec;
        break;
      }
    }
  }
  if (step == 0.0) return out;  // cannot happen for w >= 16 and a finite range; keep the bar
  const Rgb8 white{255, 255, 255};
  for (double k = std::ceil(near_m / step - 1e-9); k * step <= far_m + 1e-9 * step; k += 1.0) {
    const double value = k * step;
    const int x = left + static_cast<int>(std::lround((value - near_m) * px_per_m));
    for (int y = tick_top; y < tick_top + tick_len; ++y) {
      for (int dx = 0; dx < s; ++dx) {
        if (x + dx <= right) out(y, x + dx) = white;
      }
    }
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*f", decimals, std::abs(value) < 0.5 * step ? 0.0 : value);
    const std::string text(buf);
    const int text_w = (4 * static_cast<int>(text.size()) - 1) * s;
    const int x0 = std::clamp(x - text_w / 2, 0, std::max(0, w - text_w));
    DrawText(out, x0, text_top, text, s, white);
  }
  return out;
}

}  // namespace tofcam

#pragma once
// Simulator stage 2, radiometry (internal to tofcam::sim, docs/simulator.md): the camera equation
// per subsample (LED intensity, cos^4 falloff, radiometric constant K), surface shading (Lambert
// plus a normalised Blinn-Phong lobe), background light (ambient, lamps, glowing bulbs), mirror
// paths, the modulated phasor of each subsample and the per-pixel sums over subsamples.

#include <embree3/rtcore.h>

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "geometry.h"
#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"

namespace tofcam::sim::internal {

/// Per-pixel rates (electrons per second of integration time, per tap) of one rendering.
struct Render {
  std::vector<float> re, im;                     ///< modulated phasor, all paths
  std::vector<float> direct_re, direct_im;       ///< first-surface paths only
  std::vector<float> dc;                         ///< optical DC: active + background
  std::vector<float> scat_re, scat_im, scat_dc;  ///< scattered additions
  std::vector<float> span_m;                     ///< subsample distance span (inf when some miss)
  std::vector<float> near_m;                     ///< nearest subsample hit, m (inf when all miss)
  std::vector<float> far_m;                      ///< farthest subsample hit, m (0 when all miss)
  void Resize(std::size_t n) {
    for (auto* v : {&re, &im, &direct_re, &direct_im, &dc, &scat_re, &scat_im, &scat_dc, &span_m,
                    &near_m, &far_m}) {
      v->assign(n, 0.f);
    }
  }
};

/// Radiometric constant K of the camera equation: electrons/s per tap per (W m^-2 sr^-1) of
/// scene radiance, K = pi / (4 N^2) * pixel area * fill factor * QE * photons per joule * duty.
[[nodiscard]] double RadiometricConstant(const CameraModel& model);
/// Exponent m of the LED's intensity profile I(alpha) = I0 cos^m alpha, from its half angle
/// (I(half angle) = I0 / 2): m = -ln 2 / ln cos(half angle).
[[nodiscard]] double LedExponent(const CameraModel& model);
/// On-axis LED intensity I0 = P (m + 1) / (2 pi), W/sr (the profile integrates to P).
[[nodiscard]] double LedOnAxisWPerSr(const CameraModel& model);

/// The camera factors of every subsample and pixel.
struct SubsampleRadiometry {
  float led_on_axis_w_sr = 0, led_exponent = 1;  ///< I(alpha) = on-axis cos^m alpha
  std::vector<float> sub_active;                 ///< K * cos^4 * LED intensity / S^2
  std::vector<float> sub_bg;                     ///< K * cos^4 / S^2
  std::vector<float> pixel_bg;                   ///< sum of sub_bg over a pixel's subsamples
};

/// The camera's subsample and central rays (rays.group must be set) together with their
/// camera factors, from the model's intrinsics: subsample (i, j) of pixel (c, r) looks through
/// (c + (j + 0.5) / S - 0.5, r + (i + 0.5) / S - 0.5).
void BuildPixelRays(const CameraModel& model, int ss, PixelRays& rays, SubsampleRadiometry& rad);

/// One object's material as shading constants in float.
struct ShadeMaterial {
  float diffuse = 0, glossy = 0, shininess = 1, mirror = 0, emission = 0;
  int int_shininess = -1;  ///< the shininess when it is a whole number <= 1024, else -1
};

/// The scene's materials per object, as structs and as arrays with one entry of zeros at the end
/// (index n_obj) for rays that hit nothing, so the per-ray shading gathers without a branch.
struct MaterialTable {
  std::vector<ShadeMaterial> shade;
  std::vector<float> mat_diffuse, mat_glossy, mat_shine, mat_mirror;
  std::vector<int> mat_power;  ///< whole-number shininess (raised by squaring), else -1
  int power_bits = 0;          ///< bits of the largest mat_power
  bool any_mirror = false;
};
/// diffuse = albedo / pi; glossy = specular (n + 8) / (8 pi) when `glossy` is on, else 0.
[[nodiscard]] MaterialTable BuildMaterials(const Scene& scene, bool glossy);

/// Cosine of incidence |n . d| / |n| (at most 1) for n rays; garbage where the ray missed.
void CosIncidence(std::size_t n, const float* __restrict nx, const float* __restrict ny,
                  const float* __restrict nz, const float* __restrict dx,
                  const float* __restrict dy, const float* __restrict dz, float* __restrict cos_i);

/// Per subsample of a row (g = object hit or RTC_INVALID_GEOMETRY_ID): brdf = albedo / pi (the
/// caller adds the glossy lobe), the cosine (0 on a miss), the distance (1 on a miss, where the
/// weight is 0), the background electrons/s bg_k * radiance[g]. Misses read the zero entry n_obj
/// of the material arrays. Lists the subsamples on glossy materials in `glossy_at` and returns
/// their number.
std::size_t ShadeSurfaces(std::size_t n, unsigned n_obj, const unsigned* __restrict geom,
                          const float* __restrict t, const float* __restrict cos_in,
                          const float* __restrict bg_k, const float* __restrict diffuse,
                          const float* __restrict glossy, const float* __restrict radiance,
                          float* __restrict brdf, float* __restrict cos_out, float* __restrict dist,
                          float* __restrict bg, unsigned* __restrict glossy_at);

/// weight = active * brdf * cos.
void Weights(std::size_t n, const float* __restrict active, const float* __restrict brdf,
             const float* __restrict cos_i, float* __restrict weight);

/// Per subsample: active electrons/s = weight / d^2 (written back into weight) and the modulated
/// phasor contrast * active * exp(i 2 pi d / L), with inv_range = 1 / L (1/m).
void Phasors(std::size_t n, float inv_range, float contrast, const float* __restrict dist,
             float* __restrict weight, float* __restrict re, float* __restrict im);

/// cos^n for m values x[k] and whole numbers 0 <= n[k] < 2^bits by binary exponentiation in
/// double precision (the float nearest cos^n, see PowInt); base is scratch.
void PowIntRow(std::size_t m, int bits, const float* __restrict x, const int* __restrict n,
               double* __restrict base, double* __restrict result);

/// Scratch of AddGlossyLobes.
struct GlossyScratch {
  std::vector<float> x;              ///< cosines of incidence
  std::vector<int> n;                ///< whole-number shininess
  std::vector<double> base, result;  ///< cos^(2^k) and cos^n
};
/// Adds glossy * cos^n to brdf[i] of the n_glossy subsamples i = glossy_at[k] (cosines in
/// cos_i): whole-number shininess by exact binary exponentiation, vectorised over the
/// subsamples; any other shininess through libm exp2(n log2 cos), one by one.
void AddGlossyLobes(const MaterialTable& mats, std::size_t n_glossy, const unsigned* geom,
                    const unsigned* glossy_at, const float* cos_i, float* brdf,
                    GlossyScratch& scratch);

/// Per pixel of a row: the sums of its S^2 subsamples (phasor, DC = active + background), in
/// subsample order; the span of the subsample distances (inf when some but not all miss, 0
/// when all miss); the nearest (`near`, inf when all miss) and farthest (`far`, 0 when all miss)
/// subsample hit. Subsamples in blocks of `group` pixels as in PixelRays::Index.
void SumSubsamples(int group, int width, int s2, const float* __restrict re,
                   const float* __restrict im, const float* __restrict active,
                   const float* __restrict bg, const float* __restrict t, float* __restrict out_re,
                   float* __restrict out_im, float* __restrict out_dc, float* __restrict span,
                   float* __restrict near, float* __restrict far);

/// In-band irradiance (W/m^2) from the switched-on lamps at a surface point with normal n (no
/// shadows, inverse square); a bulb (object lamp_bulb_begin + l) does not light itself.
[[nodiscard]] float LampIrradiance(const Scene& scene, const Eigen::Vector3f& hit,
                                   const Eigen::Vector3f& n, int obj,
                                   const std::vector<char>& lamp_on);

/// What the mirror paths of a subsample need.
struct MirrorContext {
  const Scene* scene = nullptr;
  const SceneGeometry* geometry = nullptr;
  const MaterialTable* materials = nullptr;
  const float* sub_active = nullptr;  ///< SubsampleRadiometry::sub_active
  const float* sub_bg = nullptr;      ///< SubsampleRadiometry::sub_bg
  double range_m = 7.5;               ///< unambiguous range L, m
  double contrast = 1;                ///< demodulation contrast
  bool background_light = true;
  int max_bounces = 2;
};
/// Mirror paths of subsample i (batch index) whose first hit is a mirror: the LED light reaches
/// the mirrored scene and returns the same way (attenuated by mirror^2 per bounce); every further
/// surface adds its own phasor and DC to (re, im, dc). `si` indexes the per-subsample constants.
void Bounce(const MirrorContext& mc, const RayBatch& b, std::size_t i, std::size_t si,
            const Eigen::Vector3f& org, RTCIntersectContext& ctx, const std::vector<char>& lamp_on,
            float& re, float& im, float& dc);

}  // namespace tofcam::sim::internal

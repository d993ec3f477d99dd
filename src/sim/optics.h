#pragma once
// Simulator stage 3, optics (internal to tofcam::sim, docs/simulator.md): the in-camera
// scattering PSF (a sum of Gaussian lobes, blurred at reduced resolution and interpolated back)
// and one-bounce diffuse inter-reflection.

#include <Eigen/Geometry>
#include <vector>

#include "geometry.h"
#include "parallel.h"
#include "radiometry.h"
#include "tofcam/sim/camera_model.h"

namespace tofcam::sim::internal {

/// Normalised Gaussian kernel of radius max(1, ceil(3 sigma)), sigma in pixels (> 0).
[[nodiscard]] std::vector<float> GaussianKernel(double sigma);
/// Separable blur of a w x h row-major image with a kernel of odd length and zero padding (light
/// leaving the sensor is lost); tmp is scratch.
void BlurInPlace(std::vector<float>& img, std::vector<float>& tmp, int w, int h,
                 const std::vector<float>& k);
/// The same with GaussianKernel(sigma).
void BlurInPlace(std::vector<float>& img, std::vector<float>& tmp, int w, int h, double sigma);
/// BlurInPlace of a non-negative image that is zero outside rows [r0, r1) and columns [c0, c1)
/// (a box inside the image), with a non-negative kernel: only that box grown by the kernel's
/// radius is computed (the rest of img stays zero; tmp outside it is neither read nor written).
/// Every output sums the same products in the same order as BlurInPlace, less products with a
/// zero pixel, which add +0 to a sum >= +0: the same values bit for bit.
/// Its row loops run on `pool` when one is given (every output row is computed alone: the same
/// values on any number of threads).
void BlurBoxInPlace(std::vector<float>& img, std::vector<float>& tmp, int w, int h,
                    const std::vector<float>& k, int r0, int r1, int c0, int c1,
                    RowPool* pool = nullptr);

/// Scattering: reduction factor, reduced size, lobe kernels and bilinear upsampling taps.
struct ScatterPlan {
  int f = 1, rw = 0, rh = 0;
  std::vector<float> weight;  ///< per lobe, divided by f^2 (each reduced pixel sums f^2 pixels)
  std::vector<std::vector<float>> kernel;  ///< per lobe
  std::vector<int> x0, x1, y0, y1;
  std::vector<float> wx, wy;
};
/// Plans the scattering of a width x height sensor: wide lobes are smooth, so they are blurred at
/// 1/f resolution (f = clamp(min sigma / 2, 1, 8)) and interpolated back bilinearly.
[[nodiscard]] ScatterPlan PlanScatter(const std::vector<ScatterLobe>& lobes, int width, int height);
/// One channel (re, im or DC) of the scattered light: dst = sum over lobes of weight * (src
/// reduced by f, blurred, upsampled). tmp is scratch. Nothing to do when the plan has no lobe.
void ScatterChannel(const ScatterPlan& sp, int width, int height, const std::vector<float>& src,
                    std::vector<float>& dst, std::vector<float> (&tmp)[4]);

/// Inputs of the inter-reflection stage.
struct InterreflectionContext {
  const SceneGeometry* geometry = nullptr;
  const PixelRays* rays = nullptr;
  const SubsampleRadiometry* radiometry = nullptr;
  const MaterialTable* materials = nullptr;
  RowPool* pool = nullptr;
  int samples = 4;     ///< cosine-weighted hemisphere samples per evaluated point
  double range_m = 0;  ///< unambiguous range L, m
  double contrast = 1;
};
/// Per-pixel buffers of the inter-reflection stage.
struct InterreflectionBuffers {
  std::vector<float> ir_t, ir_nx, ir_ny, ir_nz, ir_re, ir_im, ir_dc;
  std::vector<int> ir_obj;
};
/// One-bounce diffuse inter-reflection (LED -> x2 -> x1 -> camera) added to `out`'s phasor and
/// DC (not to its direct part); see the comment at the definition and docs/simulator.md.
void Interreflect(const InterreflectionContext& ic, const Eigen::Isometry3d& pose,
                  InterreflectionBuffers& buf, Render& out);

}  // namespace tofcam::sim::internal

#include "tofcam/cloud/point_cloud.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "../core/avx512_forms.h"
#include "../filters/hot_loop.h"
#include "../pipeline/stage_kernels.h"
#include "tofcam/core/error.h"

// The 64-byte streaming stores (StreamBytes64): see src/core/avx512_forms.h.
#if defined(TOFCAM_AVX512_FORMS)
#include <immintrin.h>
#endif

namespace tofcam {
namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
constexpr float kMax = std::numeric_limits<float>::max();

void CheckSize(int w, int h, int cw, int ch, const char* what) {
  if (cw != w || ch != h) {
    throw Error(ErrorCode::kInvalidArgument, std::string("point cloud: ") + what + " is " +
                                                 std::to_string(cw) + "x" + std::to_string(ch) +
                                                 ", the distance image " + std::to_string(w) + "x" +
                                                 std::to_string(h));
  }
}

// n values from src (nullptr: NaN) into dst[begin, begin + n).
void CopyOrNan(const float* src, std::size_t begin, std::size_t n, std::vector<float>& dst) {
  if (src == nullptr) {
    std::fill(dst.begin() + begin, dst.begin() + begin + n, kNan);
  } else {
    std::copy(src, src + n, dst.begin() + begin);
  }
}

// Point = d × ray, NaN where d is not finite or a `mask` bit is set (flags may be null). A
// select on floats instead of a branch, restrict pointers: the loop vectorises.
TOFCAM_HOT_LOOP void Project(std::size_t n, const float* __restrict d,
                             const PixelFlags* __restrict f, std::uint16_t mask,
                             const float* __restrict rx, const float* __restrict ry,
                             const float* __restrict rz, float* __restrict x, float* __restrict y,
                             float* __restrict z) {
  if (f == nullptr) {
    for (std::size_t i = 0; i < n; ++i) {
      const float di = std::abs(d[i]) <= kMax ? d[i] : kNan;
      x[i] = di * rx[i];
      y[i] = di * ry[i];
      z[i] = di * rz[i];
    }
    return;
  }
  for (std::size_t i = 0; i < n; ++i) {
    const bool keep = (static_cast<unsigned>((f[i].bits() & mask) == 0) &
                       static_cast<unsigned>(std::abs(d[i]) <= kMax)) != 0;
    const float di = keep ? d[i] : kNan;
    x[i] = di * rx[i];
    y[i] = di * ry[i];
    z[i] = di * rz[i];
  }
}

#if defined(TOFCAM_AVX512_FORMS)
// StreamBytes on AVX-512 CPUs: one 64-byte non-temporal store per cache line, from dst's first
// line boundary on, instead of four 16-byte ones, so that no line leaves the write-combining
// buffer part-written. On the Zen 5 test machine, inside the 1 MP paper chain (a temporary
// switch in one pipeline_bench binary, five alternated runs), the chain took 2.53-2.69x its
// memcpy floor with these stores, 2.73-2.89x with 16-byte ones and 2.89-3.34x with plain stores
// (a second A/B under heavier load was within the noise).
// A cloud alone (26 MiB at 1 MP) fits in a 32 MiB L3, where plain stores write faster; in the
// chain the frame's other 40 MB pass through the same cache. docs/benchmarks.md.
TOFCAM_AVX512_DIAGNOSTICS_BEGIN
TOFCAM_AVX512_TARGET void StreamBytes64(const unsigned char* src, unsigned char* dst,
                                        std::size_t n) {
  std::size_t i = std::min(n, (64 - reinterpret_cast<std::uintptr_t>(dst) % 64) % 64);
  std::memcpy(dst, src, i);
  for (; i + 64 <= n; i += 64) {
    _mm512_stream_si512(reinterpret_cast<__m512i*>(dst + i), _mm512_loadu_si512(src + i));
  }
  std::memcpy(dst + i, src + i, n - i);
}
TOFCAM_AVX512_DIAGNOSTICS_END
#endif

// n bytes from src to dst with non-temporal stores: on AVX-512 CPUs StreamBytes64, else 64-byte
// blocks from dst's first 16-byte boundary on in four 16-byte stores (SSE2, so every x86-64 CPU;
// elsewhere a plain copy). The caller fences. Starting the 16-byte form at the first whole cache
// line instead (a large vector's data is 16 bytes past a page boundary) was measured no faster
// (two batches of interleaved pipeline_bench runs, one slower, one the same).
void StreamBytes(const void* src_v, void* dst_v, std::size_t n) {
  const auto* src = static_cast<const unsigned char*>(src_v);
  auto* dst = static_cast<unsigned char*>(dst_v);
#if defined(TOFCAM_AVX512_FORMS)
  if (internal::UseAvx512Forms()) {
    StreamBytes64(src, dst, n);
    return;
  }
#endif
  std::size_t i = 0;
#if defined(__SSE2__)
  i = std::min(n, (16 - reinterpret_cast<std::uintptr_t>(dst) % 16) % 16);
  std::memcpy(dst, src, i);
  for (; i + 64 <= n; i += 64) {
    __m128i v[4];
    std::memcpy(v, src + i, sizeof v);
    for (int k = 0; k < 4; ++k)
      _mm_stream_si128(reinterpret_cast<__m128i*>(dst + i + 16 * k), v[k]);
  }
#endif
  std::memcpy(dst + i, src + i, n - i);
}

// CloudSpan for a cloud too large for the caches (kStreamCloudBytes): the points are written
// with non-temporal stores, which spare the memory reads that ordinary stores make to fetch
// each output line first (a third of the cloud's traffic). The points are projected into an
// L1-sized block and streamed from there; the same values as the plain path.
void CloudSpanStreaming(const RayTable& rays, const PointCloudOptions& options, std::size_t begin,
                        std::size_t n, const float* d, const PixelFlags* f, const float* a,
                        const float* i, const float* dl, PointCloud& cloud) {
  const auto channel = [&](const float* src, std::vector<float>& dst) {
    if (src == nullptr) {
      std::fill(dst.begin() + begin, dst.begin() + begin + n, kNan);
    } else {
      StreamBytes(src, dst.data() + begin, n * sizeof(float));
    }
  };
  channel(a, cloud.amplitude);
  channel(i, cloud.intensity);
  channel(dl, cloud.delta_l_m);
  if (f == nullptr) {
    std::fill(cloud.flags.begin() + begin, cloud.flags.begin() + begin + n, PixelFlags());
  } else {
    StreamBytes(f, cloud.flags.data() + begin, n * sizeof(PixelFlags));
  }
  constexpr std::size_t kBlock = 1024;  // 12 KB of points
  alignas(64) float px[kBlock], py[kBlock], pz[kBlock];
  for (std::size_t b = 0; b < n; b += kBlock) {
    const std::size_t m = std::min(kBlock, n - b);
    const std::size_t at = begin + b;
    Project(m, d + b, f == nullptr ? nullptr : f + b, options.nan_mask, rays.x.data() + at,
            rays.y.data() + at, rays.z.data() + at, px, py, pz);
    StreamBytes(px, cloud.x.data() + at, m * sizeof(float));
    StreamBytes(py, cloud.y.data() + at, m * sizeof(float));
    StreamBytes(pz, cloud.z.data() + at, m * sizeof(float));
  }
#if defined(__SSE2__)
  _mm_sfence();  // the streamed lines are visible before the cloud is handed on
#endif
}

}  // namespace

bool PointCloud::IsValid(std::size_t i) const noexcept {
  return flags[i].Valid() && std::isfinite(x[i]) && std::isfinite(y[i]) && std::isfinite(z[i]);
}

std::size_t PointCloud::CountValid() const noexcept {
  std::size_t n = 0;
  for (std::size_t i = 0; i < size(); ++i) n += IsValid(i) ? 1 : 0;
  return n;
}

void PointCloud::Resize(int new_width, int new_height) {
  if (new_width < 0 || new_height < 0) {
    throw Error(ErrorCode::kInvalidArgument, "point cloud: negative size");
  }
  width = new_width;
  height = new_height;
  const std::size_t n = static_cast<std::size_t>(new_width) * static_cast<std::size_t>(new_height);
  for (auto* v : {&x, &y, &z, &amplitude, &intensity, &delta_l_m}) v->resize(n, kNan);
  flags.resize(n);
}

void PointCloud::Validate() const {
  const std::size_t n =
      static_cast<std::size_t>(std::max(width, 0)) * static_cast<std::size_t>(std::max(height, 0));
  if (width < 0 || height < 0 || x.size() != n || y.size() != n || z.size() != n ||
      amplitude.size() != n || intensity.size() != n || delta_l_m.size() != n ||
      flags.size() != n) {
    throw Error(ErrorCode::kInvalidArgument,
                "point cloud: arrays do not all hold width x height = " + std::to_string(width) +
                    "x" + std::to_string(height) + " elements");
  }
}

PointCloud MakePointCloud(const MetricFrame& frame, const RayTable& rays,
                          const PointCloudOptions& options) {
  PointCloud cloud;
  MakePointCloudInto(frame, rays, cloud, options);
  return cloud;
}

namespace kernels {

void CheckCloudInputs(const MetricFrame& frame, const RayTable& rays) {
  const int w = frame.width(), h = frame.height();
  if (frame.radial_distance_m.empty()) {
    throw Error(ErrorCode::kInvalidArgument, "point cloud: empty distance image");
  }
  if (!frame.amplitude.empty())
    CheckSize(w, h, frame.amplitude.width(), frame.amplitude.height(), "amplitude");
  if (!frame.intensity.empty())
    CheckSize(w, h, frame.intensity.width(), frame.intensity.height(), "intensity");
  if (!frame.delta_l_m.empty())
    CheckSize(w, h, frame.delta_l_m.width(), frame.delta_l_m.height(), "delta_l_m");
  if (!frame.flags.empty()) CheckSize(w, h, frame.flags.width(), frame.flags.height(), "flags");
  if (!rays.x.SameSize(w, h) || !rays.y.SameSize(w, h) || !rays.z.SameSize(w, h)) {
    throw Error(ErrorCode::kMismatch, "point cloud: ray table is " +
                                          std::to_string(rays.x.width()) + "x" +
                                          std::to_string(rays.x.height()) + ", the frame " +
                                          std::to_string(w) + "x" + std::to_string(h));
  }
}

void PrepareCloud(const MetricFrame& frame, const RayTable& rays, PointCloud& cloud) {
  CheckCloudInputs(frame, rays);
  cloud.Resize(frame.width(), frame.height());  // no-op (no allocation) at the same size
}

void CloudSpan(const RayTable& rays, const PointCloudOptions& options, std::size_t begin,
               std::size_t n, const float* d, const PixelFlags* f, const float* a, const float* i,
               const float* dl, PointCloud& cloud) {
  if (cloud.size() * kCloudBytesPerPoint >= kStreamCloudBytes) {
    CloudSpanStreaming(rays, options, begin, n, d, f, a, i, dl, cloud);
    return;
  }
  CopyOrNan(a, begin, n, cloud.amplitude);
  CopyOrNan(i, begin, n, cloud.intensity);
  CopyOrNan(dl, begin, n, cloud.delta_l_m);
  if (f == nullptr) {
    std::fill(cloud.flags.begin() + begin, cloud.flags.begin() + begin + n, PixelFlags());
  } else {
    std::copy(f, f + n, cloud.flags.begin() + begin);
  }
  Project(n, d, f, options.nan_mask, rays.x.data() + begin, rays.y.data() + begin,
          rays.z.data() + begin, cloud.x.data() + begin, cloud.y.data() + begin,
          cloud.z.data() + begin);
}

}  // namespace kernels

void MakePointCloudInto(const MetricFrame& frame, const RayTable& rays, PointCloud& cloud,
                        const PointCloudOptions& options) {
  kernels::PrepareCloud(frame, rays, cloud);
  auto data = [](const Image<float>& c) { return c.empty() ? nullptr : c.data(); };
  kernels::CloudSpan(rays, options, 0, cloud.size(), frame.radial_distance_m.data(),
                     frame.flags.empty() ? nullptr : frame.flags.data(), data(frame.amplitude),
                     data(frame.intensity), data(frame.delta_l_m), cloud);
}

}  // namespace tofcam

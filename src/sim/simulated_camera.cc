#include "tofcam/sim/simulated_camera.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <complex>
#include <condition_variable>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "fast_math.h"
#include "rng.h"
#include "saturation.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam::sim {

namespace internal {
const NormalTable& GetNormalTable() {
  static const NormalTable table;
  return table;
}
}  // namespace internal

namespace {

using internal::Rng;
constexpr double kPlanckJs = 6.62607015e-34;
constexpr float kInf = std::numeric_limits<float>::infinity();

void Require(bool ok, const std::string& what) {
  if (!ok) throw Error(ErrorCode::kInvalidArgument, "simulator options: " + what);
}

// Persistent workers for the row-parallel loops of one camera (threads - 1 of them; the calling
// thread works too). Rows are handed out in chunks from an atomic counter, so a busy core does not
// hold the frame back; results never depend on which thread ran a row, because every row has its
// own random stream and its own Embree packets (only scratch buffers are per thread). Spawning
// threads per loop, as before, cost tens of microseconds per loop and frame.
class RowPool {
 public:
  explicit RowPool(int threads) {
    for (int t = 1; t < threads; ++t) workers_.emplace_back([this, t] { Work(t); });
  }
  RowPool(const RowPool&) = delete;
  RowPool& operator=(const RowPool&) = delete;
  ~RowPool() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    for (auto& w : workers_) w.join();
  }

  // Runs body(row_begin, row_end, thread_index) over [0, rows); in parallel only when there are
  // at least min_rows_per_thread rows per thread.
  template <typename F>
  void Run(int rows, const F& body, int min_rows_per_thread = 2) {
    const int threads = static_cast<int>(workers_.size()) + 1;
    if (threads == 1 || rows < min_rows_per_thread * threads) {
      body(0, rows, 0);
      return;
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      body_ = &body;
      call_ = [](const void* b, int r0, int r1, int t) { (*static_cast<const F*>(b))(r0, r1, t); };
      rows_ = rows;
      chunk_ = std::max(1, rows / (8 * threads));
      next_.store(0, std::memory_order_relaxed);
      open_ = true;
      ++generation_;
    }
    wake_.notify_all();
    Drain(0);
    // Workers that have not joined yet (their core is busy elsewhere) are not waited for: the job
    // closes, and only those already inside it must finish.
    std::unique_lock<std::mutex> lock(mutex_);
    open_ = false;
    done_.wait(lock, [this] { return active_ == 0; });
  }

 private:
  void Drain(int thread) {
    for (;;) {
      const int r0 = next_.fetch_add(chunk_, std::memory_order_relaxed);
      if (r0 >= rows_) return;
      call_(body_, r0, std::min(r0 + chunk_, rows_), thread);
    }
  }
  void Work(int thread) {
    std::uint64_t seen = 0;
    for (;;) {
      {
        std::unique_lock<std::mutex> lock(mutex_);
        wake_.wait(lock, [&] { return stop_ || (open_ && generation_ != seen); });
        if (stop_) return;
        seen = generation_;
        ++active_;
      }
      Drain(thread);
      std::lock_guard<std::mutex> lock(mutex_);
      if (--active_ == 0) done_.notify_one();
    }
  }

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  bool stop_ = false, open_ = false;
  std::uint64_t generation_ = 0;
  int active_ = 0;
  const void* body_ = nullptr;
  void (*call_)(const void*, int, int, int) = nullptr;
  int rows_ = 0, chunk_ = 1;
  std::atomic<int> next_{0};
};

// Runs body(row_begin, row_end, thread_index) over [0, rows) on `threads` threads (the caller's
// included), spawning them per call. Grab() shadows it with the camera's persistent RowPool; this
// version stays for row loops elsewhere (e.g. if the sensor retune adds one to Bloom).
template <typename F>
void ParallelRows(int rows, int threads, const F& body) {
  if (threads <= 1 || rows < 2 * threads) {
    body(0, rows, 0);
    return;
  }
  std::vector<std::thread> pool;
  pool.reserve(static_cast<std::size_t>(threads - 1));
  for (int t = 1; t < threads; ++t) {
    pool.emplace_back([&, t] { body(rows * t / threads, rows * (t + 1) / threads, t); });
  }
  body(0, rows / threads, 0);
  for (auto& th : pool) th.join();
}

// Normalised Gaussian kernel of radius max(1, ceil(3 sigma)).
std::vector<float> GaussianKernel(double sigma) {
  const int radius = std::max(1, static_cast<int>(std::ceil(3 * sigma)));
  std::vector<float> k(2 * radius + 1);
  double sum = 0;
  for (int i = -radius; i <= radius; ++i)
    sum += k[i + radius] = static_cast<float>(std::exp(-0.5 * i * i / (sigma * sigma)));
  for (auto& v : k) v = static_cast<float>(v / sum);
  return k;
}

// Separable blur with a kernel of odd length and zero padding (light leaving the sensor is lost).
void BlurInPlace(std::vector<float>& img, std::vector<float>& tmp, int w, int h,
                 const std::vector<float>& k) {
  const int radius = static_cast<int>(k.size() / 2);
  tmp.assign(img.size(), 0.f);
  for (int r = 0; r < h; ++r) {
    const float* in = &img[static_cast<std::size_t>(r) * w];
    float* out = &tmp[static_cast<std::size_t>(r) * w];
    // Tap by tap over the columns it reaches (vectorises); every output still sums its taps in
    // increasing order from 0, so the result is the same as a per-pixel loop.
    for (int i = -radius; i <= radius; ++i) {
      const float kv = k[i + radius];
      for (int c = std::max(0, -i); c < std::min(w, w - i); ++c) out[c] += kv * in[c + i];
    }
  }
  for (int r = 0; r < h; ++r) {
    const int lo = std::max(-radius, -r), hi = std::min(radius, h - 1 - r);
    float* out = &img[static_cast<std::size_t>(r) * w];
    for (int c = 0; c < w; ++c) out[c] = 0;
    for (int i = lo; i <= hi; ++i) {
      const float kv = k[i + radius];
      const float* in = &tmp[static_cast<std::size_t>(r + i) * w];
      for (int c = 0; c < w; ++c) out[c] += kv * in[c];
    }
  }
}

// Separable Gaussian blur with zero padding (light leaving the sensor is lost).
void BlurInPlace(std::vector<float>& img, std::vector<float>& tmp, int w, int h, double sigma) {
  BlurInPlace(img, tmp, w, h, GaussianKernel(sigma));
}

// Embree ray packets of K rays (4, 8, 16): the widest the CPU runs natively is chosen at run
// time, so the library stays built for the x86-64 baseline while Embree uses AVX2 or AVX-512.
template <int K>
struct Packet;
template <>
struct Packet<4> {
  using RayHit = RTCRayHit4;
  static void Intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* r) {
    rtcIntersect4(valid, s, c, r);
  }
};
template <>
struct Packet<8> {
  using RayHit = RTCRayHit8;
  static void Intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* r) {
    rtcIntersect8(valid, s, c, r);
  }
};
template <>
struct Packet<16> {
  using RayHit = RTCRayHit16;
  static void Intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* r) {
    rtcIntersect16(valid, s, c, r);
  }
};

// Rays of one batch in structure-of-arrays form: directions in, hits out.
struct RayBatch {
  std::vector<float> dx, dy, dz;  // world directions (unit)
  std::vector<float> t;           // hit distance, inf on a miss
  std::vector<unsigned> geom;     // geometry id (= object index) or RTC_INVALID_GEOMETRY_ID
  std::vector<float> nx, ny, nz;  // geometric normal, not normalised; undefined on a miss
  void Resize(std::size_t n) {
    for (auto* v : {&dx, &dy, &dz, &t, &nx, &ny, &nz}) v->resize(n);
    geom.resize(n);
  }
};

// Intersects rays [0, n) of `b`, all from `org`, in packets of K consecutive rays.
template <int K>
void TraceK(RTCScene scene, RTCIntersectContext* ctx, const Eigen::Vector3f& org, std::size_t n,
            RayBatch& b) {
  typename Packet<K>::RayHit rh{};
  alignas(64) int valid[K];
  for (int l = 0; l < K; ++l) {
    rh.ray.org_x[l] = org.x();
    rh.ray.org_y[l] = org.y();
    rh.ray.org_z[l] = org.z();
    rh.ray.mask[l] = 0xFFFFFFFFu;
    rh.ray.id[l] = static_cast<unsigned>(l);
  }
  for (std::size_t q = 0; q < n; q += K) {
    const std::size_t m = std::min<std::size_t>(K, n - q);
    for (int l = 0; l < K; ++l) {
      const bool on = static_cast<std::size_t>(l) < m;
      const std::size_t i = on ? q + l : q;  // inactive lanes repeat a valid ray
      valid[l] = on ? -1 : 0;
      rh.ray.dir_x[l] = b.dx[i];
      rh.ray.dir_y[l] = b.dy[i];
      rh.ray.dir_z[l] = b.dz[i];
      rh.ray.tfar[l] = kInf;  // stays inf on a miss
      rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
    }
    Packet<K>::Intersect(valid, scene, ctx, &rh);
    std::copy_n(rh.ray.tfar, m, &b.t[q]);
    std::copy_n(rh.hit.geomID, m, &b.geom[q]);
    std::copy_n(rh.hit.Ng_x, m, &b.nx[q]);
    std::copy_n(rh.hit.Ng_y, m, &b.ny[q]);
    std::copy_n(rh.hit.Ng_z, m, &b.nz[q]);
  }
}

// Fills one Embree ray: origin, direction, near distance, infinite far, no hit yet.
inline void SetRay(RTCRayHit& rh, const Eigen::Vector3f& org, const Eigen::Vector3f& dir,
                   float tnear) {
  rh.ray.org_x = org.x();
  rh.ray.org_y = org.y();
  rh.ray.org_z = org.z();
  rh.ray.dir_x = dir.x();
  rh.ray.dir_y = dir.y();
  rh.ray.dir_z = dir.z();
  rh.ray.tnear = tnear;
  rh.ray.tfar = kInf;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.time = 0;
  rh.ray.flags = 0;
  rh.ray.id = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

// The same one ray at a time (CPUs without native packets).
void Trace1(RTCScene scene, RTCIntersectContext* ctx, const Eigen::Vector3f& org, std::size_t n,
            RayBatch& b) {
  for (std::size_t i = 0; i < n; ++i) {
    RTCRayHit rh;
    SetRay(rh, org, Eigen::Vector3f(b.dx[i], b.dy[i], b.dz[i]), 0.f);
    rtcIntersect1(scene, ctx, &rh);
    b.t[i] = rh.ray.tfar;
    b.geom[i] = rh.hit.geomID;
    b.nx[i] = rh.hit.Ng_x;
    b.ny[i] = rh.hit.Ng_y;
    b.nz[i] = rh.hit.Ng_z;
  }
}

// The hot row loops below are compiled twice, for the x86-64 baseline (SSE2) and for AVX2, and
// the dynamic loader picks one for the CPU (GCC/Clang function multiversioning); the library
// stays built for the baseline. Both clones do the same IEEE operations in the same order (ISO
// C++ mode contracts no FMAs, AVX2 alone enables none), so results do not depend on the CPU.
// Not under AddressSanitizer, whose run time starts after the loader has called the ifunc
// resolvers that pick the clones.
#if defined(__SANITIZE_ADDRESS__)
#define TOFCAM_SIM_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define TOFCAM_SIM_ASAN 1
#endif
#endif
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(TOFCAM_SIM_ASAN)
#define TOFCAM_SIM_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define TOFCAM_SIM_CLONES
#endif

// The loops below take __restrict pointers: without them GCC needs more run-time alias checks
// than it is willing to emit and leaves them scalar. They are kept out of line (noinline),
// because GCC forgets the __restrict of parameters once a function is inlined into a caller.

// (dx, dy, dz) = rot * (x, y, z) for n directions.
[[gnu::noinline]] TOFCAM_SIM_CLONES void RotateArrays(const Eigen::Matrix3f& rot,
                                                      const float* __restrict x,
                                                      const float* __restrict y,
                                                      const float* __restrict z, std::size_t n,
                                                      float* __restrict dx, float* __restrict dy,
                                                      float* __restrict dz) {
  const float r00 = rot(0, 0), r01 = rot(0, 1), r02 = rot(0, 2);
  const float r10 = rot(1, 0), r11 = rot(1, 1), r12 = rot(1, 2);
  const float r20 = rot(2, 0), r21 = rot(2, 1), r22 = rot(2, 2);
  for (std::size_t i = 0; i < n; ++i) {
    dx[i] = r00 * x[i] + r01 * y[i] + r02 * z[i];
    dy[i] = r10 * x[i] + r11 * y[i] + r12 * z[i];
    dz[i] = r20 * x[i] + r21 * y[i] + r22 * z[i];
  }
}

// Cosine of incidence |n . d| / |n| (at most 1) for n rays; garbage where the ray missed.
[[gnu::noinline]] TOFCAM_SIM_CLONES void CosIncidence(
    std::size_t n, const float* __restrict nx, const float* __restrict ny,
    const float* __restrict nz, const float* __restrict dx, const float* __restrict dy,
    const float* __restrict dz, float* __restrict cos_i) {
  for (std::size_t i = 0; i < n; ++i) {
    const float len = std::sqrt(nx[i] * nx[i] + ny[i] * ny[i] + nz[i] * nz[i]);
    cos_i[i] = std::min(1.f, std::abs(nx[i] * dx[i] + ny[i] * dy[i] + nz[i] * dz[i]) / len);
  }
}

// Per subsample: active electrons/s = weight / d^2 (written back into weight) and the modulated
// phasor contrast * active * exp(i 2 pi d / L).
[[gnu::noinline]] TOFCAM_SIM_CLONES void Phasors(std::size_t n, float inv_range, float contrast,
                                                 const float* __restrict dist,
                                                 float* __restrict weight, float* __restrict re,
                                                 float* __restrict im) {
  for (std::size_t i = 0; i < n; ++i) {
    const float d = dist[i];
    const float active = weight[i] / (d * d);
    float sn, cs;
    internal::SinCos2Pi(d * inv_range, sn, cs);
    weight[i] = active;
    re[i] = contrast * active * cs;
    im[i] = contrast * active * sn;
  }
}

// cos^n for the glossy subsamples of a row, n[k] >= 0 whole numbers below 2^bits: binary
// exponentiation in double precision (the float nearest cos^n, see internal::PowInt) with the
// same `bits` squarings for every lane and a bit-mask select of the factor, so it vectorises.
[[gnu::noinline]] TOFCAM_SIM_CLONES void PowIntRow(std::size_t m, int bits,
                                                   const float* __restrict x,
                                                   const int* __restrict n, double* __restrict base,
                                                   double* __restrict result) {
  for (std::size_t k = 0; k < m; ++k) {
    base[k] = x[k];
    result[k] = 1.0;
  }
  for (int bit = 0; bit < bits; ++bit) {
    for (std::size_t k = 0; k < m; ++k) {
      const std::uint64_t take = 0 - static_cast<std::uint64_t>((n[k] >> bit) & 1);
      const std::uint64_t factor = (std::bit_cast<std::uint64_t>(base[k]) & take) |
                                   (std::bit_cast<std::uint64_t>(1.0) & ~take);
      result[k] *= std::bit_cast<double>(factor);
      base[k] *= base[k];
    }
  }
}

// Per subsample of a row (g = object hit or RTC_INVALID_GEOMETRY_ID): the active electrons/s
// before the 1/d^2 falloff, weight = I(alpha) K cos^4 / S^2 * brdf * cos(incidence) with
// brdf = albedo / pi + glossy cos^n; the distance (1 on a miss, where the weight is 0); the
// background electrons/s. Misses read the zero entry n_obj of the material arrays. The gathers
// are scalar but branch-free; the rest vectorises. The subsamples on glossy materials are listed
// in `glossy_at` (n_glossy of them) and their cosines in `glossy_x`; the caller adds the lobe.
[[gnu::noinline]] TOFCAM_SIM_CLONES std::size_t ShadeSurfaces(
    std::size_t n, unsigned n_obj, const unsigned* __restrict geom, const float* __restrict t,
    const float* __restrict cos_in, const float* __restrict bg_k, const float* __restrict diffuse,
    const float* __restrict glossy, const float* __restrict radiance, float* __restrict brdf,
    float* __restrict cos_out, float* __restrict dist, float* __restrict bg,
    unsigned* __restrict glossy_at) {
  std::size_t n_glossy = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const bool hit = geom[i] != RTC_INVALID_GEOMETRY_ID;
    const unsigned g = hit ? geom[i] : n_obj;
    cos_out[i] = hit ? cos_in[i] : 0.f;  // the normal of a miss is garbage
    brdf[i] = diffuse[g];
    dist[i] = hit ? t[i] : 1.f;
    bg[i] = bg_k[i] * radiance[g];
    glossy_at[n_glossy] = static_cast<unsigned>(i);
    n_glossy += glossy[g] > 0 ? 1 : 0;
  }
  return n_glossy;
}

// weight = active * brdf * cos.
[[gnu::noinline]] TOFCAM_SIM_CLONES void Weights(std::size_t n, const float* __restrict active,
                                                 const float* __restrict brdf,
                                                 const float* __restrict cos_i,
                                                 float* __restrict weight) {
  for (std::size_t i = 0; i < n; ++i) weight[i] = active[i] * brdf[i] * cos_i[i];
}

// Per pixel of a row: the sums of its S^2 subsamples (phasor, DC = active + background), in
// subsample order, and the span of the subsample distances (inf when some but not all miss, 0
// when all miss). Blocks of G pixels as in Impl::Index(); G is a compile-time constant so the
// inner loops become vector operations.
template <int G>
void SumBlocks(int width, int s2, const float* __restrict re, const float* __restrict im,
               const float* __restrict active, const float* __restrict bg,
               const float* __restrict t, float* __restrict out_re, float* __restrict out_im,
               float* __restrict out_dc, float* __restrict span) {
  for (int c0 = 0; c0 < width; c0 += G) {
    const std::size_t base = static_cast<std::size_t>(c0) * s2;
    float sr[G], si[G], sd[G], dmin[G], dmax[G], tmax[G];
    for (int g = 0; g < G; ++g) {
      const std::size_t i = base + g;
      sr[g] = re[i];
      si[g] = im[i];
      sd[g] = active[i] + bg[i];
      dmin[g] = t[i];                      // over the hits: a miss (inf) never lowers it
      dmax[g] = t[i] < kInf ? t[i] : 0.f;  // over the hits
      tmax[g] = t[i];                      // inf when some subsample missed
    }
    for (int s = 1; s < s2; ++s) {
      for (int g = 0; g < G; ++g) {
        const std::size_t i = base + static_cast<std::size_t>(s) * G + g;
        sr[g] += re[i];
        si[g] += im[i];
        sd[g] += active[i] + bg[i];
        const float ts = t[i];
        dmin[g] = std::min(dmin[g], ts);
        dmax[g] = std::max(dmax[g], ts < kInf ? ts : 0.f);
        tmax[g] = std::max(tmax[g], ts);
      }
    }
    for (int g = 0; g < G; ++g) {
      out_re[c0 + g] = sr[g];
      out_im[c0 + g] = si[g];
      out_dc[c0 + g] = sd[g];
      // Selected with bit masks: GCC keeps a ternary over a subtraction scalar.
      const std::uint32_t hit_all = 0u - static_cast<std::uint32_t>(tmax[g] < kInf);
      const float missed = dmax[g] > 0 ? kInf : 0.f;
      span[c0 + g] =
          std::bit_cast<float>((std::bit_cast<std::uint32_t>(dmax[g] - dmin[g]) & hit_all) |
                               (std::bit_cast<std::uint32_t>(missed) & ~hit_all));
    }
  }
}

// SumBlocks<4> (the S = 2 case with 16-ray packets) written with GCC/Clang vector extensions:
// GCC's auto-vectoriser keeps the generic version scalar here.
void SumBlocks4(int width, int s2, const float* __restrict re, const float* __restrict im,
                const float* __restrict active, const float* __restrict bg,
                const float* __restrict t, float* __restrict out_re, float* __restrict out_im,
                float* __restrict out_dc, float* __restrict span) {
  using V = float __attribute__((vector_size(16)));
  const auto load = [](const float* p) {
    V v;
    std::memcpy(&v, p, sizeof v);
    return v;
  };
  const auto store = [](float* p, V v) { std::memcpy(p, &v, sizeof v); };
  const V inf = {kInf, kInf, kInf, kInf}, zero = {0, 0, 0, 0};
  for (int c0 = 0; c0 < width; c0 += 4) {
    std::size_t i = static_cast<std::size_t>(c0) * s2;
    V sr = load(re + i), si = load(im + i), sd = load(active + i) + load(bg + i);
    V ts = load(t + i);
    V dmin = ts, dmax = ts < inf ? ts : zero, tmax = ts;
    for (int s = 1; s < s2; ++s) {
      i += 4;
      sr += load(re + i);
      si += load(im + i);
      sd += load(active + i) + load(bg + i);
      ts = load(t + i);
      dmin = ts < dmin ? ts : dmin;
      const V hit = ts < inf ? ts : zero;
      dmax = dmax < hit ? hit : dmax;
      tmax = tmax < ts ? ts : tmax;
    }
    store(out_re + c0, sr);
    store(out_im + c0, si);
    store(out_dc + c0, sd);
    const V missed = dmax > zero ? inf : zero;
    store(span + c0, tmax < inf ? dmax - dmin : missed);
  }
}

[[gnu::noinline]] TOFCAM_SIM_CLONES void SumSubsamples(
    int group, int width, int s2, const float* __restrict re, const float* __restrict im,
    const float* __restrict active, const float* __restrict bg, const float* __restrict t,
    float* __restrict out_re, float* __restrict out_im, float* __restrict out_dc,
    float* __restrict span) {
  switch (group) {
    case 16:
      SumBlocks<16>(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span);
      break;
    case 8:
      SumBlocks<8>(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span);
      break;
    case 4:
      SumBlocks4(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span);
      break;
    case 2:
      SumBlocks<2>(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span);
      break;
    default:
      SumBlocks<1>(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span);
  }
}

// Sensor stage: per-frame constants of the noiseless tap means.
struct SensorConstants {
  double t_int_s = 0, dark_e = 0, global_offset_m = 0;
  double wiggle_m = 0, wiggle_cos = 1, wiggle_sin = 0;
  double m_to_rad = 0;
};

// Per thread: one row of the sensor stage.
struct SensorRow {
  std::vector<double> a[4], b[4], cos_p[4], sin_p[4];  // per rendering (tap time)
  std::vector<double> shift;                           // phase shift (rad) of rendering 0..3
  std::vector<double> mu[4], a_mean, b_mean;
  std::vector<float> sd[4];           // sqrt(mu_k): sigma of the Gaussian shot noise
  std::vector<float> sigma, noise;    // truth sigma (m) and its denominator B + read variance
  std::vector<std::uint16_t> causes;  // truth cause bits
  void Resize(int n) {
    for (int k = 0; k < 4; ++k) {
      for (auto* v : {&a[k], &b[k], &cos_p[k], &sin_p[k], &mu[k]}) v->resize(n);
      sd[k].resize(n);
    }
    for (auto* v : {&shift, &a_mean, &b_mean}) v->resize(n);
    sigma.resize(n);
    noise.resize(n);
    causes.assign(n, 0);
  }
};

// One pixel of PixelMeans; `exact` uses libm for the phase shift (for shifts beyond the range of
// the polynomial).
inline void PixelMean(const SensorConstants& k, float re, float im, float dc, float sre, float sim,
                      float sdc, float fpn, bool exact, double& a_out, double& b_out,
                      double& cos_out, double& sin_out, double& shift_out) {
  const double x_re = (re + sre) * k.t_int_s;
  const double x_im = (im + sim) * k.t_int_s;
  b_out = (dc + sdc) * k.t_int_s + k.dark_e;
  const double a = std::sqrt(x_re * x_re + x_im * x_im);
  // Unit phasor of the measured phase; (0, 0) without signal, where the phase does not matter (it
  // is multiplied by a = 0). No select (GCC would turn one into a branch and keep the loop
  // scalar): adding 1e-300 changes no reachable amplitude (a float rate times >= 1 us of
  // integration is > 1e-51 electrons, and 1e-300 is below its rounding).
  const double inv_a = 1.0 / (a + 1e-300);
  const double cr = x_re * inv_a, ci = x_im * inv_a;
  // Wiggling: the odd harmonics make the error periodic in the measured phase phi with period
  // L/4, wiggle_m sin(4 phi + phase); sin 4phi and cos 4phi come from cos phi and sin phi by the
  // double-angle formulas (exact identities; no atan2 and sin per pixel).
  const double c2 = cr * cr - ci * ci, s2 = 2 * cr * ci;
  const double c4 = c2 * c2 - s2 * s2, s4 = 2 * c2 * s2;
  const double offset_m =
      k.global_offset_m + fpn + k.wiggle_m * (s4 * k.wiggle_cos + c4 * k.wiggle_sin);
  const double shift = offset_m * k.m_to_rad;
  double sn, cs;
  if (exact) {
    sn = std::sin(shift);
    cs = std::cos(shift);
  } else {
    internal::SinCosSmallPoly(shift, sn, cs);
  }
  a_out = a;
  cos_out = cr * cs - ci * sn;
  sin_out = ci * cs + cr * sn;
  shift_out = shift;
}

// Per pixel of a row of one rendering: amplitude a and offset b (electrons) and the unit phasor
// (cos, sin) of the measured phase including the systematic distance errors (fixed pattern,
// wiggling, drift, exposure offset). Vectorised; pixels whose shift leaves the polynomial's range
// are redone exactly.
[[gnu::noinline]] TOFCAM_SIM_CLONES void PixelMeans(
    const SensorConstants& k, int n, const float* __restrict re, const float* __restrict im,
    const float* __restrict dc, const float* __restrict sre, const float* __restrict sim,
    const float* __restrict sdc, const float* __restrict fpn, double* __restrict a_out,
    double* __restrict b_out, double* __restrict cos_out, double* __restrict sin_out,
    double* __restrict shift) {
  for (int c = 0; c < n; ++c) {
    PixelMean(k, re[c], im[c], dc[c], sre[c], sim[c], sdc[c], fpn[c], false, a_out[c], b_out[c],
              cos_out[c], sin_out[c], shift[c]);
  }
  for (int c = 0; c < n; ++c) {
    if (!(std::abs(shift[c]) <= internal::kSinCosSmallMax)) {
      PixelMean(k, re[c], im[c], dc[c], sre[c], sim[c], sdc[c], fpn[c], true, a_out[c], b_out[c],
                cos_out[c], sin_out[c], shift[c]);
    }
  }
}

// mu_k = B + A cos(phi - k pi / 2): cos, sin, -cos, -sin, all from one rendering.
[[gnu::noinline]] TOFCAM_SIM_CLONES void TapMeans1(int n, const double* __restrict a,
                                                   const double* __restrict b,
                                                   const double* __restrict cp,
                                                   const double* __restrict sp,
                                                   double* __restrict mu0, double* __restrict mu1,
                                                   double* __restrict mu2, double* __restrict mu3) {
  for (int c = 0; c < n; ++c) {
    mu0[c] = b[c] + a[c] * cp[c];
    mu1[c] = b[c] + a[c] * sp[c];
    mu2[c] = b[c] - a[c] * cp[c];
    mu3[c] = b[c] - a[c] * sp[c];
  }
}

// The tap means (tap k from rendering k when there are four) and the mean amplitude and offset
// over the renderings.
void TapMeans(int n, int slots, SensorRow& sr) {
  if (slots == 1) {
    TapMeans1(n, sr.a[0].data(), sr.b[0].data(), sr.cos_p[0].data(), sr.sin_p[0].data(),
              sr.mu[0].data(), sr.mu[1].data(), sr.mu[2].data(), sr.mu[3].data());
    std::copy_n(sr.a[0].begin(), n, sr.a_mean.begin());
    std::copy_n(sr.b[0].begin(), n, sr.b_mean.begin());
    return;
  }
  for (int c = 0; c < n; ++c) {
    sr.mu[0][c] = sr.b[0][c] + sr.a[0][c] * sr.cos_p[0][c];
    sr.mu[1][c] = sr.b[1][c] + sr.a[1][c] * sr.sin_p[1][c];
    sr.mu[2][c] = sr.b[2][c] - sr.a[2][c] * sr.cos_p[2][c];
    sr.mu[3][c] = sr.b[3][c] - sr.a[3][c] * sr.sin_p[3][c];
    // Summed in slot order, as a running mean of a / 4 (exact scaling by a power of two).
    sr.a_mean[c] = sr.a[0][c] * 0.25 + sr.a[1][c] * 0.25 + sr.a[2][c] * 0.25 + sr.a[3][c] * 0.25;
    sr.b_mean[c] = sr.b[0][c] * 0.25 + sr.b[1][c] * 0.25 + sr.b[2][c] * 0.25 + sr.b[3][c] * 0.25;
  }
}

// Per pixel of a row: the standard deviation of the Gaussian shot noise of each tap and
// the ground-truth sigma L sqrt(B + s^2) / (2 sqrt(2) pi A) (0 without signal), vectorised.
[[gnu::noinline]] TOFCAM_SIM_CLONES void NoiseScales(
    int n, double read_var, double sigma_scale, const double* __restrict mu0,
    const double* __restrict mu1, const double* __restrict mu2, const double* __restrict mu3,
    const double* __restrict a_mean, const double* __restrict b_mean, float* __restrict sd0,
    float* __restrict sd1, float* __restrict sd2, float* __restrict sd3, float* __restrict sigma,
    float* __restrict noise) {
  for (int c = 0; c < n; ++c) {
    // Single precision: the normal deviates these scale are floats and the truth sigma is stored
    // as one; packed float square roots are several times faster than double ones. Only means of
    // at least kPoissonGaussMean use them, so a negative mean (NaN here) never does; clamping it
    // would let GCC branch on the constant sqrt(0) and keep the loop scalar.
    sd0[c] = std::sqrt(static_cast<float>(mu0[c]));
    sd1[c] = std::sqrt(static_cast<float>(mu1[c]));
    sd2[c] = std::sqrt(static_cast<float>(mu2[c]));
    sd3[c] = std::sqrt(static_cast<float>(mu3[c]));
    noise[c] = static_cast<float>(b_mean[c] + read_var);
    // 0 where there is no signal, selected with a bit mask: GCC may turn a select (or a product
    // with the condition) into a branch around the division, which keeps the loop scalar.
    const float s = static_cast<float>(sigma_scale / (a_mean[c] + 1e-300)) * std::sqrt(noise[c]);
    const std::uint32_t lit = 0u - static_cast<std::uint32_t>(a_mean[c] > 0);
    sigma[c] = std::bit_cast<float>(std::bit_cast<std::uint32_t>(s) & lit);
  }
}

// Ground-truth causes of a row from rendering 0 as flag bits (multipath, scattering, mixed, no
// return, beyond range), branch-free so it vectorises; the same tests as Grab's `differ` for
// cos_bias >= 0 (the caller evaluates pixel by pixel otherwise): the angle between phasors a and
// b exceeds the bias when dot < 0 or dot^2 < cos_bias^2 |a|^2 |b|^2.
[[gnu::noinline]] TOFCAM_SIM_CLONES void TruthCauses(
    int n, double cos_bias2, double t_int_s, double mixed_span_m, double range_m,
    const float* __restrict re, const float* __restrict im, const float* __restrict dre,
    const float* __restrict dim, const float* __restrict sre, const float* __restrict sim,
    const float* __restrict span, const float* __restrict td, std::uint16_t* __restrict bits) {
  const auto differ = [cos_bias2](double ar, double ai, double br, double bi) {
    const double dot = ar * br + ai * bi;
    const double norms2 = (ar * ar + ai * ai) * (br * br + bi * bi);
    return (dot < 0) | (dot * dot < cos_bias2 * norms2);
  };
  for (int c = 0; c < n; ++c) {
    const double ind_re = re[c] - dre[c], ind_im = im[c] - dim[c];
    const double ind2 = ind_re * ind_re + ind_im * ind_im;
    const double dir2 = static_cast<double>(dre[c]) * dre[c] + static_cast<double>(dim[c]) * dim[c];
    // Multipath: the indirect paths shift the phase noticeably, or outweigh the direct one.
    const bool multipath = (ind2 > 0) & ((ind2 >= dir2) | differ(re[c], im[c], dre[c], dim[c]));
    const double x_re = (re[c] + sre[c]) * t_int_s, x_im = (im[c] + sim[c]) * t_int_s;
    const bool scattering = ((sre[c] != 0) | (sim[c] != 0)) & differ(x_re, x_im, re[c], im[c]);
    const bool mixed = span[c] > mixed_span_m;
    const bool no_return = !(td[c] < kInf);
    const bool beyond = (td[c] >= range_m) & (td[c] < kInf);
    bits[c] =
        static_cast<std::uint16_t>((multipath ? static_cast<unsigned>(Flag::kMultipath) : 0u) |
                                   (scattering ? static_cast<unsigned>(Flag::kScattering) : 0u) |
                                   (mixed ? static_cast<unsigned>(Flag::kMixed) : 0u) |
                                   (no_return ? static_cast<unsigned>(Flag::kNoReturn) : 0u) |
                                   (beyond ? static_cast<unsigned>(Flag::kBeyondUnambiguous) : 0u));
  }
}

}  // namespace

SimulatorOptions SimulatorOptions::Ideal() {
  SimulatorOptions o;
  o.shot_noise = o.read_noise = o.dark_current = o.saturation = o.blooming = false;
  o.background_light = o.glossy = o.multipath = o.scattering = false;
  o.wiggling = o.fixed_pattern = o.warmup_drift = o.exposure_offset = o.motion = false;
  return o;
}

void SimulatorOptions::Validate() const {
  Require(supersampling >= 1 && supersampling <= 8, "supersampling must be in 1..8");
  Require(threads >= 1 && threads <= 64, "threads must be in 1..64");
  Require(std::isfinite(power_on_time_s) && power_on_time_s >= 0, "power_on_time_s must be >= 0");
  Require(integration_time_register >= 0, "integration_time_register must be >= 0");
  Require(max_bounces >= 0 && max_bounces <= 8, "max_bounces must be in 0..8");
  Require(interreflection_samples >= 1 && interreflection_samples <= 256,
          "interreflection_samples must be in 1..256");
  Require(std::isfinite(motion_threshold_m) && motion_threshold_m >= 0,
          "motion_threshold_m must be >= 0");
  Require(std::isfinite(truth_mixed_span_m) && truth_mixed_span_m > 0,
          "truth_mixed_span_m must be > 0");
  Require(std::isfinite(truth_bias_m) && truth_bias_m > 0, "truth_bias_m must be > 0");
}

// Per-pixel rates (electrons per second of integration time, per tap) of one rendering.
struct Render {
  std::vector<float> re, im;                     // modulated phasor, all paths
  std::vector<float> direct_re, direct_im;       // first-surface paths only
  std::vector<float> dc;                         // optical DC: active + background
  std::vector<float> scat_re, scat_im, scat_dc;  // scattered additions
  std::vector<float> span_m;                     // subsample distance span (inf when some miss)
  void Resize(std::size_t n) {
    for (auto* v : {&re, &im, &direct_re, &direct_im, &dc, &scat_re, &scat_im, &scat_dc, &span_m}) {
      v->assign(n, 0.f);
    }
  }
};

struct RenderKey {
  Eigen::Matrix<double, 3, 4> camera;
  std::vector<double> objects;  // flattened dynamic object poses
  std::vector<char> lamps;
  bool valid = false;
  bool operator==(const RenderKey& o) const {
    return valid && o.valid && camera == o.camera && objects == o.objects && lamps == o.lamps;
  }
};

struct SimulatedCamera::Impl {
  Scene scene;
  CameraModel model;
  SimulatorOptions options;
  int width = 0, height = 0, ss = 1;
  double modulation_hz = 20e6;
  double range_m = 7.5;

  RTCDevice device = nullptr;
  RTCScene rtc_scene = nullptr;
  std::vector<unsigned> geometry_ids;          // per object
  std::vector<char> dynamic_object;            // per object
  std::vector<Eigen::Isometry3d> object_pose;  // last committed
  bool committed = false;

  // Per subsample, camera frame, as arrays so the per-frame loops vectorise, in the order the rays
  // go to Embree: a row is split into blocks of `group` neighbouring pixels, and a block holds
  // their subsample s = i S + j (i, j in 0..S-1) for s = 0, 1, .., S^2 - 1 in turn, so one packet
  // of `packet_width` = group * S^2 rays covers group x 1 pixels (2 x 2 subsamples each at S = 2,
  // 16 rays) and the per-pixel sums over subsamples are vector adds (see Index()).
  std::vector<float> sub_x, sub_y, sub_z;  // unit direction
  std::vector<float> sub_active;           // K * cos^4 * LED intensity / S^2
  std::vector<float> sub_bg;               // K * cos^4 / S^2
  // Per pixel: the central ray (ground truth). For odd S it is the centre subsample's ray.
  std::vector<float> center_x, center_y, center_z;
  std::vector<float> pixel_bg;                   // sum of sub_bg over a pixel's subsamples
  float led_on_axis_w_sr = 0, led_exponent = 1;  // I(α) = on-axis cos^m α
  // One-bounce inter-reflection per pixel: first surface (distance, object, normal) and the
  // incoming complex irradiance of the evaluated points (docs/simulator.md).
  std::vector<float> ir_t, ir_nx, ir_ny, ir_nz, ir_re, ir_im, ir_dc;
  std::vector<int> ir_obj;
  int packet_width = 1;  // Embree packet size the CPU runs natively (16, 8, 4 or 1)
  int group = 1;         // pixels per block (1: pixel-major, when S^2 does not divide a packet)

  // Position of subsample s of column c within a row's arrays.
  std::size_t Index(int s, int c) const {
    const int s2 = ss * ss;
    return static_cast<std::size_t>(c / group) * group * s2 + static_cast<std::size_t>(s) * group +
           c % group;
  }

  Image<float> fpn_m;
  std::vector<Render> renders;  // 1 or 4 (one per tap time)
  std::vector<RenderKey> keys;
  RenderKey truth_key;
  std::vector<float> truth_distance;
  std::vector<float> taps[4];
  std::vector<float> tmp2;  // scratch of Bloom's blur
  // Per pixel of the current frame: noiseless offset plus read-noise variance (electrons), the
  // denominator of the truth sigma, so blooming can add its charge to it.
  std::vector<float> truth_noise_e2;
  std::vector<float> bloom_mean;  // mean spilled charge per tap, electrons (blooming)
  // Per thread: one row of rays and the shading terms of each ray.
  struct Scratch {
    RayBatch rays;
    std::vector<float> cos_i;   // cosine of incidence
    std::vector<float> weight;  // active electrons / s before the 1/d^2 and phase: I cos4 brdf cos
    std::vector<float> dist;    // hit distance, 1 on a miss (weight 0) so the phase stays finite
    std::vector<float> bg;      // background radiance times sub_bg
    std::vector<float> re, im;  // phasor of each subsample
    std::vector<float> scatter_tmp[4];            // reduced images of one scattering channel
    std::vector<unsigned> glossy_at;              // subsamples on glossy materials
    std::vector<float> glossy_x;                  // their cosines of incidence
    std::vector<int> glossy_n;                    // their whole-number shininess
    std::vector<double> glossy_base, glossy_pow;  // cos^(2^k) and cos^n
    std::vector<int> mirrored;  // subsamples whose first hit is a mirror (bounces follow)
    SensorRow sensor;
  };
  std::vector<Scratch> scratch;  // per thread
  std::unique_ptr<RowPool> pool;
  // Per object: its material's shading constants in float.
  struct ShadeMaterial {
    float diffuse = 0, glossy = 0, shininess = 1, mirror = 0, emission = 0;
    int int_shininess = -1;  // the shininess when it is a whole number <= 1024, else -1
  };
  std::vector<ShadeMaterial> shade;
  // The same as arrays indexed by object, plus one entry of zeros at the end for rays that hit
  // nothing, so the per-ray shading gathers without a branch.
  std::vector<float> mat_diffuse, mat_glossy, mat_shine, mat_mirror;
  std::vector<int> mat_power;  // whole-number shininess (raised by squaring), else -1
  int power_bits = 0;          // bits of the largest mat_power
  bool any_mirror = false;
  // Scattering: reduction factor, reduced size, lobe kernels and bilinear upsampling taps.
  struct ScatterPlan {
    int f = 1, rw = 0, rh = 0;
    std::vector<float> weight;  // per lobe, divided by f^2 (each reduced pixel sums f^2 pixels)
    std::vector<std::vector<float>> kernel;  // per lobe
    std::vector<int> x0, x1, y0, y1;
    std::vector<float> wx, wy;
  } scatter;

  ~Impl() {
    if (rtc_scene) rtcReleaseScene(rtc_scene);
    if (device) rtcReleaseDevice(device);
  }

  void Build() {
    width = model.intrinsics.width;
    height = model.intrinsics.height;
    ss = options.supersampling;
    device = rtcNewDevice("threads=1,set_affinity=0");
    if (!device) throw Error(ErrorCode::kInternal, "Embree: cannot create device");
    rtc_scene = rtcNewScene(device);
    // Few objects move (and only in dynamic scenes): a full-quality static BVH pays off, and the
    // re-commit after moving a small object stays cheap.
    rtcSetSceneBuildQuality(rtc_scene, RTC_BUILD_QUALITY_MEDIUM);
    const int n = static_cast<int>(scene.objects.size());
    geometry_ids.resize(n);
    dynamic_object.resize(n);
    object_pose.assign(n, Eigen::Isometry3d::Identity());
    for (int i = 0; i < n; ++i) {
      const SceneObject& o = scene.objects[i];
      dynamic_object[i] = !o.motion.IsStatic();
      RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
      rtcSetGeometryBuildQuality(
          g, dynamic_object[i] ? RTC_BUILD_QUALITY_REFIT : RTC_BUILD_QUALITY_HIGH);
      rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                              o.vertices.size());
      auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
          g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), o.triangles.size()));
      for (std::size_t t = 0; t < o.triangles.size(); ++t) {
        for (int k = 0; k < 3; ++k) {
          const int v = o.triangles[t][k];
          if (v < 0 || v >= static_cast<int>(o.vertices.size())) {
            rtcReleaseGeometry(g);
            throw Error(ErrorCode::kInvalidArgument,
                        "scene object '" + o.name + "' has a vertex index out of range");
          }
          idx[3 * t + k] = static_cast<unsigned>(v);
        }
      }
      object_pose[i] = o.motion.At(0.0);
      WriteVertices(g, o, object_pose[i]);
      rtcCommitGeometry(g);
      geometry_ids[i] = rtcAttachGeometry(rtc_scene, g);
      rtcReleaseGeometry(g);
    }
    rtcCommitScene(rtc_scene);
    committed = true;

    // Radiometric constant K: e-/s per tap per (W m^-2 sr^-1) of scene radiance (camera equation).
    const double pixel_area = model.pixel_pitch_x_um * model.pixel_pitch_y_um * 1e-12;
    const double photons_per_j = model.wavelength_nm * 1e-9 / (kPlanckJs * kSpeedOfLightMPerS);
    const double k = kPi / (4 * model.f_number * model.f_number) * pixel_area * model.fill_factor *
                     model.quantum_efficiency * photons_per_j * model.tap_duty;
    const double m_exp = -std::log(2.0) / std::log(std::cos(model.led_half_angle_deg * kPi / 180));
    const double led_on_axis = model.led_power_w * (m_exp + 1) / (2 * kPi);  // W/sr
    const int s2 = ss * ss;
    const std::size_t np = static_cast<std::size_t>(width) * height;
    for (auto* v : {&sub_x, &sub_y, &sub_z, &sub_active, &sub_bg}) v->resize(np * s2);
    if (rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED)) {
      packet_width = 16;
    } else if (rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED)) {
      packet_width = 8;
    } else if (rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED)) {
      packet_width = 4;
    }
    group = 1;
    if (s2 <= packet_width && packet_width % s2 == 0 && width % (packet_width / s2) == 0) {
      group = packet_width / s2;
    }
    for (auto* v : {&center_x, &center_y, &center_z}) v->resize(np);
    pixel_bg.assign(np, 0.f);
    led_on_axis_w_sr = static_cast<float>(led_on_axis);
    led_exponent = static_cast<float>(m_exp);
    for (int r = 0; r < height; ++r) {
      for (int c = 0; c < width; ++c) {
        const std::size_t p = static_cast<std::size_t>(r) * width + c;
        const Eigen::Vector3f cd = model.intrinsics.Unproject({c, r}).cast<float>();
        center_x[p] = cd.x();
        center_y[p] = cd.y();
        center_z[p] = cd.z();
        for (int i = 0; i < ss; ++i) {
          for (int j = 0; j < ss; ++j) {
            const Eigen::Vector2d px(c + (j + 0.5) / ss - 0.5, r + (i + 0.5) / ss - 0.5);
            const Eigen::Vector3d d = model.intrinsics.Unproject(px);
            const double cos_a = d.z();
            const double c4 = cos_a * cos_a * cos_a * cos_a;
            const std::size_t s = static_cast<std::size_t>(r) * width * s2 + Index(i * ss + j, c);
            sub_x[s] = static_cast<float>(d.x());
            sub_y[s] = static_cast<float>(d.y());
            sub_z[s] = static_cast<float>(d.z());
            sub_bg[s] = static_cast<float>(k * c4 / s2);
            pixel_bg[p] += sub_bg[s];
            sub_active[s] = static_cast<float>(k * c4 * led_on_axis * std::pow(cos_a, m_exp) / s2);
          }
        }
      }
    }
    PlanScatter();
    // Fixed-pattern map: a bowl reaching fpn_bowl_m at the corners plus seeded pixel spread.
    fpn_m = Image<float>(width, height, 0.f);
    if (options.fixed_pattern) {
      Rng rng(model.unit_seed ^ 0xF1F0'0000'0000'0001ull);
      const double cx = model.intrinsics.cx_px, cy = model.intrinsics.cy_px;
      const double hx = std::max(cx, width - 1 - cx), hy = std::max(cy, height - 1 - cy);
      for (int r = 0; r < height; ++r) {
        for (int c = 0; c < width; ++c) {
          const double u = (c - cx) / std::max(hx, 1.0), v = (r - cy) / std::max(hy, 1.0);
          fpn_m(r, c) = static_cast<float>(model.fpn_bowl_m * 0.5 * (u * u + v * v) +
                                           model.fpn_spread_m * rng.Normal());
        }
      }
    }
    truth_distance.assign(np, kInf);
    scratch.resize(static_cast<std::size_t>(options.threads));
    pool = std::make_unique<RowPool>(options.threads);
    shade.resize(scene.objects.size());
    for (std::size_t i = 0; i < scene.objects.size(); ++i) {
      const Material& m = scene.materials.at(static_cast<std::size_t>(scene.objects[i].material));
      ShadeMaterial& sm = shade[i];
      sm.diffuse = static_cast<float>(m.albedo / kPi);
      // Normalised Blinn-Phong lobe; emitter and camera coincide, so the half vector is the
      // viewing direction and the lobe is cos^n of the incidence angle.
      sm.glossy =
          options.glossy ? static_cast<float>(m.specular * (m.shininess + 8) / (8 * kPi)) : 0.f;
      sm.shininess = static_cast<float>(m.shininess);
      if (m.shininess >= 0 && m.shininess <= 1024 && m.shininess == std::floor(m.shininess)) {
        sm.int_shininess = static_cast<int>(m.shininess);
      }
      sm.mirror = static_cast<float>(m.mirror);
      sm.emission = static_cast<float>(m.emission_w_m2_sr);
    }
    const std::size_t n_obj = scene.objects.size();
    mat_diffuse.assign(n_obj + 1, 0.f);
    mat_glossy.assign(n_obj + 1, 0.f);
    mat_shine.assign(n_obj + 1, 0.f);
    mat_mirror.assign(n_obj + 1, 0.f);
    mat_power.assign(n_obj + 1, -1);
    for (std::size_t i = 0; i < n_obj; ++i) {
      const ShadeMaterial& sm = shade[i];
      mat_diffuse[i] = sm.diffuse;
      mat_glossy[i] = sm.glossy;
      mat_shine[i] = sm.shininess;
      mat_power[i] = sm.int_shininess;
      if (sm.glossy > 0) {
        while ((std::max(0, mat_power[i]) >> power_bits) != 0) ++power_bits;
      }
      mat_mirror[i] = sm.mirror;
      any_mirror = any_mirror || sm.mirror > 0;
    }
    for (auto& t : taps) t.assign(np, 0.f);
    truth_noise_e2.assign(np, 0.f);
  }

  static void WriteVertices(RTCGeometry g, const SceneObject& o, const Eigen::Isometry3d& pose) {
    auto* v = static_cast<float*>(rtcGetGeometryBufferData(g, RTC_BUFFER_TYPE_VERTEX, 0));
    const Eigen::Matrix3f rot = pose.linear().cast<float>();
    const Eigen::Vector3f tr = pose.translation().cast<float>();
    for (std::size_t i = 0; i < o.vertices.size(); ++i) {
      const Eigen::Vector3f w = rot * o.vertices[i] + tr;
      v[3 * i] = w.x();
      v[3 * i + 1] = w.y();
      v[3 * i + 2] = w.z();
    }
  }

  // Moves dynamic objects to their pose at `time_s`; recommits only when something moved.
  void PlaceObjects(double time_s) {
    bool changed = false;
    for (std::size_t i = 0; i < scene.objects.size(); ++i) {
      if (!dynamic_object[i]) continue;
      const Eigen::Isometry3d pose = scene.objects[i].motion.At(time_s);
      if (pose.matrix() == object_pose[i].matrix()) continue;
      object_pose[i] = pose;
      RTCGeometry g = rtcGetGeometry(rtc_scene, geometry_ids[i]);
      WriteVertices(g, scene.objects[i], pose);
      rtcUpdateGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0);
      rtcCommitGeometry(g);
      changed = true;
    }
    if (changed) rtcCommitScene(rtc_scene);
  }

  // The scene's camera pose is the optical centre at pan angle 0; the pan unit's rotation centre
  // sits camera_offset_m behind it, so pan 0 leaves the camera where the scene put it.
  Eigen::Isometry3d CameraPose(double time_s, double pan_rad) const {
    return scene.camera.At(time_s) * Eigen::Translation3d(-scene.pan_unit.camera_offset_m) *
           scene.pan_unit.CameraToBase(pan_rad);
  }

  RenderKey MakeKey(double time_s, double pan_rad) const {
    RenderKey key;
    key.camera = CameraPose(time_s, pan_rad).matrix().topRows<3>();
    for (std::size_t i = 0; i < scene.objects.size(); ++i) {
      if (!dynamic_object[i]) continue;
      const Eigen::Matrix<double, 3, 4> m =
          scene.objects[i].motion.At(time_s).matrix().topRows<3>();
      key.objects.insert(key.objects.end(), m.data(), m.data() + 12);
    }
    for (const Lamp& l : scene.lamps) key.lamps.push_back(l.OnAt(time_s) ? 1 : 0);
    key.valid = true;
    return key;
  }

  // Casts one ray; returns the hit distance (inf on miss), geometric normal and object.
  float Cast(const Eigen::Vector3f& org, const Eigen::Vector3f& dir, float tnear,
             RTCIntersectContext& ctx, Eigen::Vector3f& normal, int& object) const {
    RTCRayHit rh;
    SetRay(rh, org, dir, tnear);
    rtcIntersect1(rtc_scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return kInf;
    normal = Eigen::Vector3f(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z).normalized();
    object = static_cast<int>(rh.hit.geomID);  // attached in object order, ids 0..n-1
    return rh.ray.tfar;
  }

  // Intersects the first n rays of `b` (all from org) in the CPU's native packet width.
  void Trace(RTCIntersectContext* ctx, const Eigen::Vector3f& org, std::size_t n,
             RayBatch& b) const {
    switch (packet_width) {
      case 16:
        TraceK<16>(rtc_scene, ctx, org, n, b);
        break;
      case 8:
        TraceK<8>(rtc_scene, ctx, org, n, b);
        break;
      case 4:
        TraceK<4>(rtc_scene, ctx, org, n, b);
        break;
      default:
        Trace1(rtc_scene, ctx, org, n, b);
    }
  }

  // World directions of n camera-frame directions (x, y, z) into b.dx.. starting at `at`.
  static void Rotate(const Eigen::Matrix3f& rot, const float* x, const float* y, const float* z,
                     std::size_t n, RayBatch& b, std::size_t at) {
    RotateArrays(rot, x, y, z, n, b.dx.data() + at, b.dy.data() + at, b.dz.data() + at);
  }

  // Renders rates at one time into `out` (no scattering yet). With `truth`, the central ray of
  // every pixel is cast in the same batches and truth_distance is filled too (same time and pose).
  void RenderAt(double time_s, double pan_rad, Render& out, bool truth) {
    PlaceObjects(time_s);
    const Eigen::Isometry3d pose = CameraPose(time_s, pan_rad);
    const Eigen::Matrix3f rot = pose.linear().cast<float>();
    const Eigen::Vector3f org = pose.translation().cast<float>();
    std::vector<char> lamp_on(scene.lamps.size());
    bool any_lamp = false;
    for (std::size_t l = 0; l < scene.lamps.size(); ++l) {
      lamp_on[l] = scene.lamps[l].OnAt(time_s);
      any_lamp = any_lamp || lamp_on[l];
    }
    const bool background = options.background_light;
    const bool lamps = background && any_lamp;
    // Background radiance of each object apart from the lamps' light: ambient, glowing bulbs.
    std::vector<float> object_radiance(scene.objects.size(), 0.f);
    if (background) {
      const float ambient = static_cast<float>(scene.ambient_irradiance_w_m2);
      for (std::size_t g = 0; g < object_radiance.size(); ++g) {
        object_radiance[g] = shade[g].diffuse * ambient;
        const int bulb = static_cast<int>(g) - scene.lamp_bulb_begin;
        if (bulb >= 0 && bulb < static_cast<int>(lamp_on.size()) && lamp_on[bulb]) {
          object_radiance[g] += shade[g].emission;
        }
      }
    }
    const float inv_range = static_cast<float>(1.0 / range_m);
    const float contrast = static_cast<float>(model.demodulation_contrast);
    const bool bounces = options.multipath && options.max_bounces > 0;
    const int s2 = ss * ss;
    const std::size_t np = static_cast<std::size_t>(width) * height;
    if (out.re.size() != np) out.Resize(np);
    // Odd S: the centre subsample is the pixel's central ray (same direction bit for bit).
    const bool truth_from_center = truth && ss % 2 == 1;
    const int center_sub = (ss / 2) * ss + ss / 2;
    const std::size_t ns = static_cast<std::size_t>(width) * s2;  // subsample rays of a row
    const std::size_t nr = ns + (truth && !truth_from_center ? width : 0);
    const auto n_obj = static_cast<unsigned>(scene.objects.size());
    object_radiance.push_back(0.f);  // rays that hit nothing
    pool->Run(height, [&](int r0, int r1, int thread) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      Scratch& sc = scratch[thread];
      RayBatch& b = sc.rays;
      b.Resize(nr);
      for (auto* v : {&sc.cos_i, &sc.weight, &sc.dist, &sc.bg, &sc.re, &sc.im}) v->resize(ns);
      sc.glossy_at.resize(ns);
      for (int r = r0; r < r1; ++r) {
        const std::size_t row_sub = static_cast<std::size_t>(r) * width * s2;
        const std::size_t row_px = static_cast<std::size_t>(r) * width;
        Rotate(rot, &sub_x[row_sub], &sub_y[row_sub], &sub_z[row_sub], ns, b, 0);
        if (nr > ns) {
          Rotate(rot, &center_x[row_px], &center_y[row_px], &center_z[row_px], width, b, ns);
        }
        // Primary rays of the row (and the truth rays) in coherent packets.
        Trace(&ctx, org, nr, b);
        if (truth) {
          for (int c = 0; c < width; ++c) {
            truth_distance[row_px + c] =
                truth_from_center ? b.t[Index(center_sub, c)] : b.t[ns + c];
          }
        }
        // Per subsample: cosine of incidence, BRDF, background (vectorised, no branches).
        CosIncidence(ns, b.nx.data(), b.ny.data(), b.nz.data(), b.dx.data(), b.dy.data(),
                     b.dz.data(), sc.cos_i.data());
        const std::size_t n_glossy = ShadeSurfaces(
            ns, n_obj, b.geom.data(), b.t.data(), sc.cos_i.data(), &sub_bg[row_sub],
            mat_diffuse.data(), mat_glossy.data(), object_radiance.data(), sc.re.data(),
            sc.im.data(), sc.dist.data(), sc.bg.data(), sc.glossy_at.data());
        AddGlossyLobes(n_glossy, b, sc);
        Weights(ns, &sub_active[row_sub], sc.re.data(), sc.im.data(), sc.weight.data());
        if (lamps) {
          for (std::size_t i = 0; i < ns; ++i) {
            const unsigned g = b.geom[i];
            if (g == RTC_INVALID_GEOMETRY_ID) continue;
            const Eigen::Vector3f n = Eigen::Vector3f(b.nx[i], b.ny[i], b.nz[i]).normalized();
            const Eigen::Vector3f hit = org + b.t[i] * Eigen::Vector3f(b.dx[i], b.dy[i], b.dz[i]);
            sc.bg[i] += sub_bg[row_sub + i] * shade[g].diffuse *
                        LampIrradiance(hit, n, static_cast<int>(g), lamp_on);
          }
        }
        sc.mirrored.clear();
        if (bounces && any_mirror) {
          for (std::size_t i = 0; i < ns; ++i) {
            const unsigned g = b.geom[i];
            if (g != RTC_INVALID_GEOMETRY_ID && shade[g].mirror > 0) {
              sc.mirrored.push_back(static_cast<int>(i));
            }
          }
        }
        // Phasors: amplitude falls with d^2, phase 2 pi d / L (vectorised, no libm).
        Phasors(ns, inv_range, contrast, sc.dist.data(), sc.weight.data(), sc.re.data(),
                sc.im.data());
        SumSubsamples(group, width, s2, sc.re.data(), sc.im.data(), sc.weight.data(), sc.bg.data(),
                      b.t.data(), &out.re[row_px], &out.im[row_px], &out.dc[row_px],
                      &out.span_m[row_px]);
        std::copy_n(&out.re[row_px], width, &out.direct_re[row_px]);
        std::copy_n(&out.im[row_px], width, &out.direct_im[row_px]);
        for (int i : sc.mirrored) {
          const std::size_t block = static_cast<std::size_t>(i) / (group * s2);
          const std::size_t p = row_px + block * group + static_cast<std::size_t>(i) % group;
          Bounce(b, static_cast<std::size_t>(i), row_sub + i, org, ctx, lamp_on, out.re[p],
                 out.im[p], out.dc[p]);
        }
      }
    });
    if (options.interreflection) Interreflect(pose, out);
    if (options.scattering) Scatter(out);
  }

  // One-bounce diffuse inter-reflection: the LED lights a point x2, which reflects diffusely
  // onto the pixel's surface point x1, which reflects diffusely into the camera. Per evaluated
  // pixel (every second one in x and y), the irradiance arriving at x1 over that path is
  // estimated from cosine-weighted hemisphere samples (E = π/N Σ L2, L2 the radiance of x2 towards
  // x1, with a shadow ray from x2 to the emitter), as a phasor of the path LED -> x2 -> x1. It is
  // then averaged over the evaluated points on the same surface within 3 px (same object, depth
  // within 5 %, normals within 25°): indirect light varies slowly along a surface, and this turns
  // N samples into ~12 N. Every pixel adds (ρ1/π) E times its camera factor, at the phase of the
  // full path, as indirect light (not in direct_re/im, so the truth flags it as multipath when it
  // shifts the phase). Diffuse only (no glossy or mirror at either end), no lamp or ambient light
  // in the bounce; the sample pattern is fixed per pixel, so a static scene gives a static result.
  void Interreflect(const Eigen::Isometry3d& pose, Render& out) {
    const int n = options.interreflection_samples;
    const Eigen::Matrix3f rot = pose.linear().cast<float>();
    const Eigen::Vector3f org = pose.translation().cast<float>();
    const Eigen::Vector3f axis = rot.col(2);
    const std::size_t np = static_cast<std::size_t>(width) * height;
    for (auto* v : {&ir_t, &ir_nx, &ir_ny, &ir_nz, &ir_re, &ir_im, &ir_dc}) v->assign(np, 0.f);
    ir_obj.assign(np, -1);
    // Half the round-trip path in units of L: the phase of a path of total length P is π P / L.
    const float half_cycles = static_cast<float>(0.5 / range_m);
    const float two_pi = static_cast<float>(2 * kPi);
    pool->Run(height, [&](int r0, int r1, int /*thread*/) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      std::vector<RTCRayHit> rays(static_cast<std::size_t>(n));
      std::vector<RTCRay> shadow(static_cast<std::size_t>(n));
      std::vector<int> lit(static_cast<std::size_t>(n));
      for (int r = r0; r < r1; ++r) {
        for (int c = 0; c < width; ++c) {
          const std::size_t p = static_cast<std::size_t>(r) * width + c;
          const Eigen::Vector3f dir = rot * Eigen::Vector3f(center_x[p], center_y[p], center_z[p]);
          Eigen::Vector3f n1;
          int g1 = -1;
          const float t1 = Cast(org, dir, 0.f, ctx, n1, g1);
          if (!(t1 < kInf)) continue;
          if (n1.dot(dir) > 0) n1 = -n1;  // the side the camera sees
          ir_t[p] = t1;
          ir_obj[p] = g1;
          ir_nx[p] = n1.x();
          ir_ny[p] = n1.y();
          ir_nz[p] = n1.z();
          if (r % 2 != 0 || c % 2 != 0) continue;  // evaluated on every second pixel
          const Eigen::Vector3f x1 = org + t1 * dir + 1e-4f * n1;
          const Eigen::Vector3f helper =
              std::abs(n1.x()) > 0.9f ? Eigen::Vector3f(0, 1, 0) : Eigen::Vector3f(1, 0, 0);
          const Eigen::Vector3f tb = helper.cross(n1).normalized(), bb = n1.cross(tb);
          // A stratified pattern (R1 sequence) rotated per pixel by a hash of its index.
          const std::uint64_t h = (p + 1) * 0x9E3779B97F4A7C15ull;
          const float off1 = static_cast<float>((h >> 40) & 0xFFFFFF) / 16777216.0f;
          const float off2 = static_cast<float>((h >> 16) & 0xFFFFFF) / 16777216.0f;
          for (int k = 0; k < n; ++k) {
            float u1 = (static_cast<float>(k) + 0.5f) / static_cast<float>(n) + off1;
            float u2 = static_cast<float>(k) * 0.6180339887f + off2;
            u1 -= std::floor(u1);
            u2 -= std::floor(u2);
            const float rr = std::sqrt(u1), phi = two_pi * u2;
            const Eigen::Vector3f w = tb * (rr * std::cos(phi)) + bb * (rr * std::sin(phi)) +
                                      n1 * std::sqrt(std::max(0.f, 1.f - u1));
            SetRay(rays[k], x1, w, 0.f);
          }
          rtcIntersect1M(rtc_scene, &ctx, rays.data(), static_cast<unsigned>(n), sizeof(RTCRayHit));
          int m = 0;
          for (int k = 0; k < n; ++k) {
            if (rays[k].hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
            const RTCRay& in = rays[k].ray;
            const Eigen::Vector3f x2 = Eigen::Vector3f(in.org_x, in.org_y, in.org_z) +
                                       in.tfar * Eigen::Vector3f(in.dir_x, in.dir_y, in.dir_z);
            const Eigen::Vector3f to = org - x2;
            const float d2 = to.norm();
            RTCRay& sr = shadow[m];
            sr.org_x = x2.x();
            sr.org_y = x2.y();
            sr.org_z = x2.z();
            sr.dir_x = to.x() / d2;
            sr.dir_y = to.y() / d2;
            sr.dir_z = to.z() / d2;
            sr.tnear = 1e-4f;
            sr.tfar = d2 * (1.f - 1e-5f);
            sr.mask = 0xFFFFFFFFu;
            sr.time = 0;
            sr.flags = 0;
            sr.id = 0;
            lit[m++] = k;
          }
          if (m == 0) continue;
          rtcOccluded1M(rtc_scene, &ctx, shadow.data(), static_cast<unsigned>(m), sizeof(RTCRay));
          float re = 0, im = 0, dc = 0;
          for (int j = 0; j < m; ++j) {
            if (!(shadow[j].tfar >= 0)) continue;  // Embree sets tfar to -inf when occluded
            const RTCRayHit& hit = rays[lit[j]];
            const auto g2 = static_cast<int>(hit.hit.geomID);
            if (shade[g2].diffuse <= 0) continue;
            const Eigen::Vector3f w(hit.ray.dir_x, hit.ray.dir_y, hit.ray.dir_z);
            const Eigen::Vector3f n2 =
                Eigen::Vector3f(hit.hit.Ng_x, hit.hit.Ng_y, hit.hit.Ng_z).normalized();
            const Eigen::Vector3f to_led(shadow[j].dir_x, shadow[j].dir_y, shadow[j].dir_z);
            // The LED must light the side of x2 that faces x1.
            const float cos_led = n2.dot(to_led), cos_back = -n2.dot(w);
            if (cos_led * cos_back <= 0) continue;
            const float d2 = shadow[j].tfar / (1.f - 1e-5f);
            const float cos_axis = -axis.dot(to_led);
            if (!(cos_axis > 0)) continue;
            const float intensity = led_on_axis_w_sr * std::pow(cos_axis, led_exponent);
            const float radiance = shade[g2].diffuse * intensity * std::abs(cos_led) / (d2 * d2);
            const float cycles = half_cycles * (d2 + hit.ray.tfar);
            re += radiance * std::cos(two_pi * cycles);
            im += radiance * std::sin(two_pi * cycles);
            dc += radiance;
          }
          const float scale = static_cast<float>(kPi) / static_cast<float>(n);
          ir_re[p] = scale * re;
          ir_im[p] = scale * im;
          ir_dc[p] = scale * dc;
        }
      }
    });
    // Smooth along surfaces and add to the rendering.
    const float contrast = static_cast<float>(model.demodulation_contrast);
    pool->Run(height, [&](int r0, int r1, int /*thread*/) {
      for (int r = r0; r < r1; ++r) {
        for (int c = 0; c < width; ++c) {
          const std::size_t p = static_cast<std::size_t>(r) * width + c;
          const int g = ir_obj[p];
          if (g < 0 || shade[g].diffuse <= 0) continue;
          float re = 0, im = 0, dc = 0;
          int count = 0;
          for (int rr = std::max(0, (r - 3 + 1) & ~1); rr <= std::min(height - 1, r + 3); rr += 2) {
            for (int cc = std::max(0, (c - 3 + 1) & ~1); cc <= std::min(width - 1, c + 3);
                 cc += 2) {
              const std::size_t q = static_cast<std::size_t>(rr) * width + cc;
              if (ir_obj[q] != g || std::abs(ir_t[q] - ir_t[p]) > 0.05f * ir_t[p] ||
                  ir_nx[q] * ir_nx[p] + ir_ny[q] * ir_ny[p] + ir_nz[q] * ir_nz[p] < 0.9f) {
                continue;
              }
              re += ir_re[q];
              im += ir_im[q];
              dc += ir_dc[q];
              ++count;
            }
          }
          if (count == 0) continue;
          // Rate = camera factor x (ρ1/π) x E, at the phase of the leg x1 -> camera added.
          const float k = pixel_bg[p] * shade[g].diffuse / static_cast<float>(count);
          const float leg = two_pi * half_cycles * ir_t[p];
          const float cs = std::cos(leg), sn = std::sin(leg);
          out.re[p] += contrast * k * (re * cs - im * sn);
          out.im[p] += contrast * k * (re * sn + im * cs);
          out.dc[p] += k * dc;
        }
      }
    });
  }

  // Adds glossy * cos^n to the BRDF (sc.re) of the row's subsamples on glossy materials (cosines
  // in sc.im): whole-number shininess by exact binary exponentiation, vectorised over the
  // subsamples; any other shininess through libm exp2(n log2 cos), one by one.
  void AddGlossyLobes(std::size_t n_glossy, const RayBatch& b, Scratch& sc) const {
    if (n_glossy == 0) return;
    sc.glossy_x.resize(n_glossy);
    sc.glossy_n.resize(n_glossy);
    sc.glossy_base.resize(n_glossy);
    sc.glossy_pow.resize(n_glossy);
    for (std::size_t k = 0; k < n_glossy; ++k) {
      const std::size_t i = sc.glossy_at[k];
      sc.glossy_x[k] = sc.im[i];
      sc.glossy_n[k] = std::max(0, mat_power[b.geom[i]]);
    }
    PowIntRow(n_glossy, power_bits, sc.glossy_x.data(), sc.glossy_n.data(), sc.glossy_base.data(),
              sc.glossy_pow.data());
    for (std::size_t k = 0; k < n_glossy; ++k) {
      const std::size_t i = sc.glossy_at[k];
      const unsigned g = b.geom[i];
      const float cos_i = sc.glossy_x[k];
      if (!(cos_i > 0)) continue;  // grazing: the weight is 0 anyway (times cos)
      const float lobe = mat_power[g] >= 0 ? static_cast<float>(sc.glossy_pow[k])
                                           : std::exp2(mat_shine[g] * std::log2(cos_i));
      sc.re[i] += mat_glossy[g] * lobe;
    }
  }

  // In-band irradiance from the switched-on lamps at a surface point (no shadows); a bulb does
  // not light itself.
  float LampIrradiance(const Eigen::Vector3f& hit, const Eigen::Vector3f& n, int obj,
                       const std::vector<char>& lamp_on) const {
    float irradiance = 0;
    const int bulb = obj - scene.lamp_bulb_begin;
    for (std::size_t l = 0; l < scene.lamps.size(); ++l) {
      if (!lamp_on[l] || static_cast<int>(l) == bulb) continue;
      const Eigen::Vector3f to = scene.lamps[l].position_m.cast<float>() - hit;
      const float d2 = std::max(to.squaredNorm(), 1e-6f);
      irradiance += static_cast<float>(scene.lamps[l].ir_power_w / (4 * kPi)) *
                    std::abs(n.dot(to)) / (d2 * std::sqrt(d2));
    }
    return irradiance;
  }

  // Mirror paths of subsample i (batch index) whose first hit is a mirror: the LED light reaches
  // the mirrored scene and returns the same way; every further surface adds its own phasor (not
  // to the direct part). `si` indexes the per-subsample constants.
  void Bounce(const RayBatch& b, std::size_t i, std::size_t si, const Eigen::Vector3f& org,
              RTCIntersectContext& ctx, const std::vector<char>& lamp_on, float& re, float& im,
              float& dc) const {
    const float two_pi_over_l = static_cast<float>(2 * kPi / range_m);
    const float contrast = static_cast<float>(model.demodulation_contrast);
    const float ambient =
        options.background_light ? static_cast<float>(scene.ambient_irradiance_w_m2) : 0.f;
    Eigen::Vector3f dir(b.dx[i], b.dy[i], b.dz[i]);
    Eigen::Vector3f n = Eigen::Vector3f(b.nx[i], b.ny[i], b.nz[i]).normalized();
    float t = b.t[i];
    int obj = static_cast<int>(b.geom[i]);
    Eigen::Vector3f o = org;
    float path = t, att = 1;
    for (int bounce = 1;; ++bounce) {
      const ShadeMaterial& prev = shade[obj];
      if (prev.mirror <= 0 || bounce > options.max_bounces) break;
      att *= prev.mirror * prev.mirror;
      o = o + t * dir;
      dir = dir - 2 * n.dot(dir) * n;
      t = Cast(o, dir, 1e-4f, ctx, n, obj);
      if (!(t < kInf)) break;
      path += t;
      const ShadeMaterial& m = shade[obj];
      const float cos_i = std::min(1.f, std::abs(n.dot(dir)));
      float brdf = m.diffuse;
      if (m.glossy > 0 && cos_i > 0) {
        brdf += m.glossy * std::exp2(m.shininess * std::log2(cos_i));
      }
      const float active = sub_active[si] * att * brdf * cos_i / (path * path);
      const float a = contrast * active;
      const float phase = two_pi_over_l * path;
      re += a * std::cos(phase);
      im += a * std::sin(phase);
      float radiance = 0;
      if (options.background_light) {
        const Eigen::Vector3f hit = o + t * dir;
        radiance = m.diffuse * (ambient + LampIrradiance(hit, n, obj, lamp_on));
        const int bulb = obj - scene.lamp_bulb_begin;
        if (bulb >= 0 && bulb < static_cast<int>(lamp_on.size()) && lamp_on[bulb]) {
          radiance += m.emission;
        }
      }
      dc += active + sub_bg[si] * att * radiance;
    }
  }

  // Ground truth alone (when the taps were rendered at other times).
  void TruthAt(double time_s, double pan_rad) {
    const Eigen::Isometry3d pose = CameraPose(time_s, pan_rad);
    const Eigen::Matrix3f rot = pose.linear().cast<float>();
    const Eigen::Vector3f org = pose.translation().cast<float>();
    pool->Run(height, [&](int r0, int r1, int thread) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      RayBatch& b = scratch[thread].rays;
      b.Resize(static_cast<std::size_t>(width));
      for (int r = r0; r < r1; ++r) {
        const std::size_t row_px = static_cast<std::size_t>(r) * width;
        Rotate(rot, &center_x[row_px], &center_y[row_px], &center_z[row_px], width, b, 0);
        Trace(&ctx, org, width, b);
        std::copy(b.t.begin(), b.t.begin() + width, truth_distance.begin() + row_px);
      }
    });
  }

  void PlanScatter() {
    ScatterPlan& sp = scatter;
    double min_sigma = 1e9;
    for (const ScatterLobe& l : model.scattering) min_sigma = std::min(min_sigma, l.sigma_px);
    // Wide lobes are smooth: blur at 1/f resolution (f <= sigma/2) and interpolate back.
    sp.f = std::clamp(static_cast<int>(min_sigma / 2), 1, 8);
    const int f = sp.f;
    sp.rw = (width + f - 1) / f;
    sp.rh = (height + f - 1) / f;
    sp.weight.clear();
    sp.kernel.clear();
    for (const ScatterLobe& l : model.scattering) {
      if (l.weight <= 0) continue;
      sp.weight.push_back(static_cast<float>(l.weight) / static_cast<float>(f * f));
      sp.kernel.push_back(GaussianKernel(l.sigma_px / f));
    }
    // Bilinear upsampling; reduced pixel (i, j) covers full pixels [f*i, f*i + f).
    auto taps = [f](int n, int reduced, std::vector<int>& i0, std::vector<int>& i1,
                    std::vector<float>& w) {
      i0.resize(n);
      i1.resize(n);
      w.resize(n);
      for (int x = 0; x < n; ++x) {
        const double y = (x + 0.5) / f - 0.5;
        i0[x] = std::clamp(static_cast<int>(std::floor(y)), 0, reduced - 1);
        i1[x] = std::min(i0[x] + 1, reduced - 1);
        w[x] = static_cast<float>(std::clamp(y - i0[x], 0.0, 1.0));
      }
    };
    taps(width, sp.rw, sp.x0, sp.x1, sp.wx);
    taps(height, sp.rh, sp.y0, sp.y1, sp.wy);
  }

  void Scatter(Render& out) {
    const ScatterPlan& sp = scatter;
    if (sp.weight.empty()) {
      std::fill(out.scat_re.begin(), out.scat_re.end(), 0.f);
      std::fill(out.scat_im.begin(), out.scat_im.end(), 0.f);
      std::fill(out.scat_dc.begin(), out.scat_dc.end(), 0.f);
      return;
    }
    const int f = sp.f, rw = sp.rw, rh = sp.rh;
    const std::vector<float>* src[3] = {&out.re, &out.im, &out.dc};
    std::vector<float>* dst[3] = {&out.scat_re, &out.scat_im, &out.scat_dc};
    // The three channels (re, im, DC) are independent: one per task on the row pool.
    pool->Run(
        3,
        [&](int ch0, int ch1, int thread) {
          Scratch& sc = scratch[thread];
          std::vector<float>& reduced = sc.scatter_tmp[0];
          std::vector<float>& blurred = sc.scatter_tmp[1];
          std::vector<float>& work = sc.scatter_tmp[2];
          std::vector<float>& acc = sc.scatter_tmp[3];
          for (int ch = ch0; ch < ch1; ++ch) {
            reduced.assign(static_cast<std::size_t>(rw) * rh, 0.f);
            for (int r = 0; r < height; ++r) {
              float* dst_row = &reduced[static_cast<std::size_t>(r / f) * rw];
              const float* src_row = &(*src[ch])[static_cast<std::size_t>(r) * width];
              for (int c0 = 0, j = 0; c0 < width; c0 += f, ++j) {
                float a = 0;
                for (int c = c0; c < std::min(c0 + f, width); ++c) a += src_row[c];
                dst_row[j] += a;
              }
            }
            acc.assign(reduced.size(), 0.f);
            for (std::size_t l = 0; l < sp.weight.size(); ++l) {
              blurred = reduced;
              BlurInPlace(blurred, work, rw, rh, sp.kernel[l]);
              const float wl = sp.weight[l];
              for (std::size_t i = 0; i < acc.size(); ++i) acc[i] += wl * blurred[i];
            }
            // Bilinear upsampling: interpolate along the rows of the reduced image first (each
            // reduced row once), then between the two rows of every full row.
            work.resize(static_cast<std::size_t>(rh) * width);
            for (int j = 0; j < rh; ++j) {
              const float* a = &acc[static_cast<std::size_t>(j) * rw];
              float* o = &work[static_cast<std::size_t>(j) * width];
              for (int c = 0; c < width; ++c) {
                o[c] = (1 - sp.wx[c]) * a[sp.x0[c]] + sp.wx[c] * a[sp.x1[c]];
              }
            }
            std::vector<float>& d = *dst[ch];
            for (int r = 0; r < height; ++r) {
              const float* a = &work[static_cast<std::size_t>(sp.y0[r]) * width];
              const float* b = &work[static_cast<std::size_t>(sp.y1[r]) * width];
              const float wy = sp.wy[r];
              float* o = &d[static_cast<std::size_t>(r) * width];
              for (int c = 0; c < width; ++c) o[c] = (1 - wy) * a[c] + wy * b[c];
            }
          }
        },
        1);
  }

  // Saturation physics on the noisy tap charges (electrons). A storage site holds at most the
  // full well. Of a full site's excess, `overflow` spills over the barrier into the pixel's other
  // sites, which share its photo-gate (filled evenly into the sites with room left): the taps of a
  // saturating pixel equalise, so its offset keeps rising while its amplitude collapses. Of the
  // charge that cannot stay in the pixel, `bloom` leaves it for the neighbours (Gaussian of
  // blooming_sigma_px); the rest goes to the drain.
  // Bloomed charge is charge, not light: it reaches a neighbour's photo-gate at times unrelated to
  // the 20 MHz gate clock, so the neighbour's demodulation sorts it into its four taps equally on
  // average. It raises the neighbour's offset (intensity) but not its amplitude, and each electron
  // lands independently, so every tap receives a Poisson count of it (when shot noise is on):
  // the extra noise eq. 2 predicts from the raised intensity.
  // Returns true when charge bloomed; bloom_mean then holds the mean spill per tap of every pixel.
  bool Saturate(double full_well, double overflow, double bloom, std::uint64_t frame_seed,
                bool shot_noise) {
    const std::size_t np = taps[0].size();
    const float fw = static_cast<float>(full_well);
    const float keep_share = static_cast<float>(overflow);
    const float out_share = static_cast<float>(bloom);
    bool any = false;
    bloom_mean.assign(np, 0.f);
    for (std::size_t i = 0; i < np; ++i) {
      float n[4];
      for (int k = 0; k < 4; ++k) n[k] = taps[k][i];
      const float out = internal::OverflowPixel(n, fw, keep_share);
      for (int k = 0; k < 4; ++k) taps[k][i] = n[k];
      const float spill = out_share * out;
      if (spill > 0) {
        bloom_mean[i] = spill / 4;  // per tap of the receiving pixel
        any = true;
      }
    }
    if (!any) return false;
    BlurInPlace(bloom_mean, tmp2, width, height, model.blooming_sigma_px);
    for (int r = 0; r < height; ++r) {
      Rng rng(frame_seed ^ 0xB10060000000000Dull ^
              (static_cast<std::uint64_t>(r) * 0xA24BAED4963EE407ull));
      for (int c = 0; c < width; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * width + c;
        const float mean = bloom_mean[i];
        if (!(mean > 0)) continue;
        for (auto& tap : taps) {
          tap[i] += shot_noise ? static_cast<float>(rng.Poisson(mean)) : mean;
        }
      }
    }
    return true;
  }
};

SimulatedCamera::SimulatedCamera(Scene scene, CameraModel model, SimulatorOptions options)
    : impl_(std::make_unique<Impl>()) {
  options.Validate();
  model.Validate();
  if (scene.objects.empty()) throw Error(ErrorCode::kInvalidArgument, "scene has no objects");
  impl_->scene = std::move(scene);
  impl_->model = std::move(model);
  impl_->options = options;
  impl_->modulation_hz = impl_->model.modulation_frequencies_hz.front();
  impl_->range_m = UnambiguousRangeM(impl_->modulation_hz);
  info_ = impl_->model.Info(impl_->modulation_hz);
  integration_register_ = options.integration_time_register == 0
                              ? impl_->model.default_integration_register
                              : options.integration_time_register;
  if (integration_register_ < impl_->model.min_integration_register ||
      integration_register_ > impl_->model.max_integration_register) {
    throw Error(ErrorCode::kInvalidArgument,
                "simulator options: integration_time_register " +
                    std::to_string(integration_register_) + " outside [" +
                    std::to_string(impl_->model.min_integration_register) + ", " +
                    std::to_string(impl_->model.max_integration_register) + "]");
  }
  impl_->Build();
}

SimulatedCamera::~SimulatedCamera() = default;

const Scene& SimulatedCamera::scene() const noexcept { return impl_->scene; }
const CameraModel& SimulatedCamera::model() const noexcept { return impl_->model; }
const SimulatorOptions& SimulatedCamera::options() const noexcept { return impl_->options; }
const Image<float>& SimulatedCamera::FixedPatternOffsetM() const noexcept { return impl_->fpn_m; }

double SimulatedCamera::WarmupOffsetM(double time_s) const noexcept {
  if (!impl_->options.warmup_drift) return 0.0;
  return impl_->model.warmup_amplitude_m *
         std::exp(-(impl_->options.power_on_time_s + time_s) / impl_->model.warmup_time_constant_s);
}

void SimulatedCamera::SetIntegrationTimeRegister(int reg) {
  if (reg < info_.min_integration_register || reg > info_.max_integration_register) {
    throw Error(ErrorCode::kInvalidArgument,
                "integration-time register " + std::to_string(reg) + " outside [" +
                    std::to_string(info_.min_integration_register) + ", " +
                    std::to_string(info_.max_integration_register) + "]");
  }
  integration_register_ = reg;
}

void SimulatedCamera::SetModulationFrequencyHz(double hz) {
  for (double f : impl_->model.modulation_frequencies_hz) {
    if (std::isfinite(hz) && std::abs(f - hz) <= 1.0) {
      if (f != impl_->modulation_hz) {
        impl_->modulation_hz = f;
        impl_->range_m = UnambiguousRangeM(f);
        info_.modulation_frequency_hz = f;
        for (auto& k : impl_->keys) k.valid = false;  // phases change
        impl_->truth_key.valid = false;
      }
      return;
    }
  }
  std::string known;
  for (double f : impl_->model.modulation_frequencies_hz) {
    known += (known.empty() ? "" : ", ") + std::to_string(static_cast<long long>(f)) + " Hz";
  }
  throw Error(ErrorCode::kInvalidArgument, "modulation frequency " + std::to_string(hz) +
                                               " Hz not supported by " + info_.model + " (" +
                                               known + ")");
}

void SimulatedCamera::SetDistanceOffsetRegister(int reg) {
  if (reg < 0 || reg > 65535) {
    throw Error(ErrorCode::kInvalidArgument,
                "distance-offset register " + std::to_string(reg) + " outside [0, 65535]");
  }
  offset_register_ = reg;
}

void SimulatedCamera::SetPanAngleRad(double angle_rad) {
  if (!std::isfinite(angle_rad)) {
    throw Error(ErrorCode::kInvalidArgument, "pan angle must be finite");
  }
  pan_override_rad_ = angle_rad;
}

double SimulatedCamera::PanAngleRad() const {
  if (pan_override_rad_) return *pan_override_rad_;
  const auto& sched = impl_->scene.pan_schedule;
  if (sched.empty()) return 0.0;
  const double t = next_start_s_;
  if (t <= sched.front().time_s) return sched.front().angle_deg * kPi / 180;
  if (t >= sched.back().time_s) return sched.back().angle_deg * kPi / 180;
  for (std::size_t i = 1; i < sched.size(); ++i) {
    if (t < sched[i].time_s) {
      const double w = (t - sched[i - 1].time_s) / (sched[i].time_s - sched[i - 1].time_s);
      return (sched[i - 1].angle_deg + w * (sched[i].angle_deg - sched[i - 1].angle_deg)) * kPi /
             180;
    }
  }
  return sched.back().angle_deg * kPi / 180;
}

std::optional<Frame> SimulatedCamera::Grab() {
  Impl& im = *impl_;
  const SimulatorOptions& opt = im.options;
  const CameraModel& model = im.model;
  const int w = im.width, h = im.height;
  const double t_int_us = info_.IntegrationTimeUs(integration_register_);
  const double t_int_s = t_int_us * 1e-6;
  const double start = next_start_s_;
  const double mid = start + t_int_s / 2;
  const double pan = PanAngleRad();

  // Does anything move noticeably during this exposure? Compare the poses at its two ends.
  bool split = false;
  if (opt.motion) {
    const RenderKey a = im.MakeKey(start, pan), b = im.MakeKey(start + t_int_s, pan);
    const double lever = 5.0;  // m: rotation error measured at a 5 m lever arm
    auto moved = [&](const auto& x, const auto& y) {
      // ||R1 - R2||_F = 2 sqrt(2) sin(angle / 2), about sqrt(2) * angle for small angles.
      return (x.col(3) - y.col(3)).norm() +
                 lever * (x.template leftCols<3>() - y.template leftCols<3>()).norm() /
                     std::sqrt(2.0) >
             opt.motion_threshold_m;
    };
    split = moved(a.camera, b.camera);
    for (std::size_t i = 0; !split && i + 12 <= a.objects.size(); i += 12) {
      split = moved(Eigen::Map<const Eigen::Matrix<double, 3, 4>>(&a.objects[i]),
                    Eigen::Map<const Eigen::Matrix<double, 3, 4>>(&b.objects[i]));
    }
  }
  const int slots = split ? 4 : 1;
  im.renders.resize(4);
  im.keys.resize(4);
  const RenderKey truth_key = im.MakeKey(mid, pan);
  for (int s = 0; s < slots; ++s) {
    const double t = split ? start + (s + 0.5) * t_int_s / 4 : mid;
    const RenderKey key = im.MakeKey(t, pan);
    if (!(key == im.keys[s])) {
      // One rendering at mid-exposure also casts the ground-truth rays (same time and pose).
      const bool with_truth = !split && !(truth_key == im.truth_key);
      im.RenderAt(t, pan, im.renders[s], with_truth);
      im.keys[s] = key;
      if (with_truth) im.truth_key = truth_key;
    }
  }
  if (!(truth_key == im.truth_key)) {
    im.PlaceObjects(mid);
    im.TruthAt(mid, pan);
    im.truth_key = truth_key;
  }

  Frame frame;
  frame.distance = Image<std::uint16_t>(w, h);
  frame.amplitude = Image<std::uint16_t>(w, h);
  frame.intensity = Image<std::uint16_t>(w, h);
  GroundTruth truth;
  truth.radial_distance_m = Image<float>(w, h);
  truth.causes = Image<PixelFlags>(w, h);
  truth.sigma_m = Image<float>(w, h);

  const double range = im.range_m;
  const double two_pi = 2 * kPi;
  const double dark =
      opt.dark_current ? model.dark_current_e_per_s * model.tap_duty * t_int_s : 0.0;
  double global_offset_m = 0;
  if (opt.warmup_drift) global_offset_m += WarmupOffsetM(mid);
  if (opt.exposure_offset) global_offset_m += model.exposure_offset_m_per_ms * t_int_us * 1e-3;
  const double read_sigma = opt.read_noise ? model.read_noise_e : 0.0;
  const double full_well = model.full_well_e;
  const double bias_rad = opt.truth_bias_m * two_pi / range;
  const std::uint64_t frame_seed =
      opt.seed * 0x9E3779B97F4A7C15ull + sequence_ * 0xD1B54A32D192ED03ull;

  // Row loops run on the camera's persistent workers (the demodulation loop below too).
  const auto ParallelRows = [&im](int rows, int /*threads*/, const auto& body) {
    im.pool->Run(rows, body);
  };
  // Taps: noiseless means, then shot and read noise per tap.
  const double cos_bias = std::cos(std::min(bias_rad, kPi));
  // True when the angle between phasors (ar, ai) and (br, bi) exceeds the truth bias, i.e.
  // dot < cos_bias |a| |b|; squared (no square root) where both sides are known to be >= 0.
  auto differ = [cos_bias](double ar, double ai, double br, double bi) {
    const double dot = ar * br + ai * bi;
    const double norms2 = (ar * ar + ai * ai) * (br * br + bi * bi);
    if (cos_bias >= 0) return dot < 0 || dot * dot < cos_bias * cos_bias * norms2;
    return dot < cos_bias * std::sqrt(norms2);
  };
  SensorConstants sk;
  sk.t_int_s = t_int_s;
  sk.dark_e = dark;
  sk.global_offset_m = global_offset_m;
  sk.wiggle_m = opt.wiggling ? model.wiggle_amplitude_m : 0.0;
  sk.wiggle_cos = std::cos(model.wiggle_phase_rad);
  sk.wiggle_sin = std::sin(model.wiggle_phase_rad);
  sk.m_to_rad = two_pi / range;
  const double read_var = read_sigma * read_sigma;
  const double sigma_scale = range / (2 * std::sqrt(2.0) * kPi);
  ParallelRows(h, opt.threads, [&](int r0, int r1, int thread) {
    SensorRow& sr = im.scratch[thread].sensor;
    sr.Resize(w);
    for (int r = r0; r < r1; ++r) {
      const std::size_t row = static_cast<std::size_t>(r) * w;
      const float* fpn = &im.fpn_m[row];  // zeros when the fixed pattern is off
      // Noiseless means of the four taps (each from its own rendering when the scene moves).
      for (int slot = 0; slot < slots; ++slot) {
        const Render& rd = im.renders[slot];
        PixelMeans(sk, w, &rd.re[row], &rd.im[row], &rd.dc[row], &rd.scat_re[row], &rd.scat_im[row],
                   &rd.scat_dc[row], fpn, sr.a[slot].data(), sr.b[slot].data(),
                   sr.cos_p[slot].data(), sr.sin_p[slot].data(), sr.shift.data());
      }
      TapMeans(w, slots, sr);
      NoiseScales(w, read_var, sigma_scale, sr.mu[0].data(), sr.mu[1].data(), sr.mu[2].data(),
                  sr.mu[3].data(), sr.a_mean.data(), sr.b_mean.data(), sr.sd[0].data(),
                  sr.sd[1].data(), sr.sd[2].data(), sr.sd[3].data(), sr.sigma.data(),
                  sr.noise.data());
      // Shot and read noise, one random stream per row.
      Rng rng(frame_seed ^ (static_cast<std::uint64_t>(r) * 0xA24BAED4963EE407ull));
      // Draws in the order of Rng::Poisson then the read noise, per tap: drawing shot plus read
      // noise as one N(mu, mu + s^2) would be the same distribution with half the draws, but a
      // different realisation, and statistics evaluated on single frames (experiments fig. 6-7)
      // depend on the realisation.
      for (int c = 0; c < w; ++c) {
        for (int k = 0; k < 4; ++k) {
          double v = sr.mu[k][c];
          if (opt.shot_noise) {
            // Rng::Poisson with sqrt(mean) precomputed (vectorised) in the Gaussian regime.
            v = v >= internal::kPoissonGaussMean ? v + sr.sd[k][c] * rng.Normal() : rng.Poisson(v);
          }
          if (read_sigma > 0) v += read_sigma * rng.Normal();
          im.taps[k][row + c] = static_cast<float>(v);
        }
      }
      // Ground truth.
      const Render& rd = im.renders[0];
      if (cos_bias >= 0) {
        TruthCauses(w, cos_bias * cos_bias, t_int_s, opt.truth_mixed_span_m, range, &rd.re[row],
                    &rd.im[row], &rd.direct_re[row], &rd.direct_im[row], &rd.scat_re[row],
                    &rd.scat_im[row], &rd.span_m[row], &im.truth_distance[row], sr.causes.data());
      }
      for (int c = 0; c < w; ++c) {
        const std::size_t p = row + c;
        PixelFlags causes(sr.causes[c]);
        const float td = im.truth_distance[p];
        if (cos_bias < 0) {
          // Truth causes from the noiseless components.
          const double ind_re = rd.re[p] - rd.direct_re[p], ind_im = rd.im[p] - rd.direct_im[p];
          const double ind2 = ind_re * ind_re + ind_im * ind_im;
          const double dir2 = static_cast<double>(rd.direct_re[p]) * rd.direct_re[p] +
                              static_cast<double>(rd.direct_im[p]) * rd.direct_im[p];
          // Multipath: the indirect paths shift the phase noticeably, or outweigh the direct one.
          if (ind2 > 0 &&
              (ind2 >= dir2 || differ(rd.re[p], rd.im[p], rd.direct_re[p], rd.direct_im[p]))) {
            causes.Set(Flag::kMultipath);
          }
          if (rd.scat_re[p] != 0 || rd.scat_im[p] != 0) {
            const double re = (rd.re[p] + rd.scat_re[p]) * t_int_s;
            const double imag = (rd.im[p] + rd.scat_im[p]) * t_int_s;
            if (differ(re, imag, rd.re[p], rd.im[p])) causes.Set(Flag::kScattering);
          }
          if (rd.span_m[p] > opt.truth_mixed_span_m) causes.Set(Flag::kMixed);
          if (!(td < kInf)) causes.Set(Flag::kNoReturn);
          if (td >= range && td < kInf) causes.Set(Flag::kBeyondUnambiguous);
        }
        for (int k = 1; k < slots; ++k) {
          if (differ(im.renders[k].re[p], im.renders[k].im[p], rd.re[p], rd.im[p])) {
            causes.Set(Flag::kMotion);
            break;
          }
        }
        truth.radial_distance_m[p] = td;
        truth.sigma_m[p] = sr.sigma[c];
        im.truth_noise_e2[p] = sr.noise[c];
        truth.causes[p] = causes;
      }
    }
  });
  if (opt.saturation) {
    if (im.Saturate(full_well, model.overflow_fraction,
                    opt.blooming ? model.blooming_fraction : 0.0, frame_seed, opt.shot_noise)) {
      // The spilled charge is offset without amplitude: it raises the true shot-noise sigma by
      // sqrt((B + spill) / B) (B including the read-noise variance).
      for (std::size_t p = 0; p < im.bloom_mean.size(); ++p) {
        if (im.bloom_mean[p] > 0 && im.truth_noise_e2[p] > 0) {
          truth.sigma_m[p] *=
              std::sqrt((im.truth_noise_e2[p] + im.bloom_mean[p]) / im.truth_noise_e2[p]);
        }
      }
    }
  }
  // Clip, demodulate and quantise.
  const double gain = model.gain_reg_per_e;
  ParallelRows(h, opt.threads, [&](int r0, int r1, int /*thread*/) {
    for (int r = r0; r < r1; ++r) {
      for (int c = 0; c < w; ++c) {
        const std::size_t p = static_cast<std::size_t>(r) * w + c;
        double n[4];
        bool saturated = false;
        for (int k = 0; k < 4; ++k) {
          n[k] = std::max(0.0, static_cast<double>(im.taps[k][p]));
          if (opt.saturation && n[k] >= full_well) {
            n[k] = full_well;
            saturated = true;
          }
        }
        const double i_comp = n[0] - n[2], q_comp = n[1] - n[3];
        double phase = std::atan2(q_comp, i_comp);
        if (phase < 0) phase += two_pi;
        const double amp = std::sqrt(i_comp * i_comp + q_comp * q_comp) / 2;
        const double off = (n[0] + n[1] + n[2] + n[3]) / 4;
        long long reg = std::llround(phase / two_pi * kDistanceRegisterSpan) + offset_register_;
        frame.distance[p] = static_cast<std::uint16_t>(reg & 0xFFFF);
        frame.amplitude[p] = static_cast<std::uint16_t>(
            std::min<double>(kMaxSignalRegister, std::round(gain * amp)));
        frame.intensity[p] = static_cast<std::uint16_t>(
            std::min<double>(kMaxSignalRegister, std::round(gain * off)));
        if (saturated || gain * off > kMaxSignalRegister) truth.causes[p].Set(Flag::kSaturated);
      }
    }
  });

  frame.info.sequence = sequence_;
  frame.info.timestamp_ns = static_cast<std::int64_t>(std::llround(mid * 1e9));
  frame.info.integration_time_register = integration_register_;
  frame.info.integration_time_us = t_int_us;
  frame.info.modulation_frequency_hz = im.modulation_hz;
  frame.info.pan_angle_rad = pan;
  frame.info.distance_offset_register = offset_register_;
  frame.info.camera_model = model.name;
  frame.info.has_intensity = true;
  frame.truth = std::move(truth);

  const double period =
      std::max(1.0 / model.max_frame_rate_hz, t_int_s + model.readout_time_us * 1e-6);
  next_start_s_ = start + period;
  ++sequence_;
  if (opt.real_time) {
    // Frame n is due when its successor's exposure would start, on a clock anchored at the first
    // throttled frame.
    using Clock = std::chrono::steady_clock;
    if (!real_time_origin_)
      real_time_origin_ = Clock::now() - std::chrono::duration_cast<Clock::duration>(
                                             std::chrono::duration<double>(start));
    std::this_thread::sleep_until(
        *real_time_origin_ +
        std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(next_start_s_)));
  }
  return frame;
}

}  // namespace tofcam::sim

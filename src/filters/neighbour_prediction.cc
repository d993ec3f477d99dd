#include "tofcam/filters/neighbour_prediction.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

#include "hot_loop.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

[[noreturn]] void Bad(const std::string& what) { throw Error(ErrorCode::kInvalidArgument, what); }

constexpr int kMaxRadius = 5;
constexpr int kBlockPixels = 256;
// The usable range of a support pixel (file comment): within it q = 1/d <= 100, σ_q² =
// (ΔL/d²)² in [1e-26, 1e12], a pair's weight 4 / (σ_qa² + σ_qb²) <= 4e26, and every weighted
// sum of at most 60 pairs stays below 1e31 in single precision.
constexpr float kMinDistanceM = 0.01f, kMaxDistanceM = 1e4f;
constexpr float kMinDeltaLM = 1e-5f, kMaxDeltaLM = 100.0f;

void CheckInput(const MetricFrame& frame, const NeighbourPredictionOptions& options) {
  options.Validate();
  const int w = frame.width(), h = frame.height();
  if (w <= 0 || h <= 0) Bad("neighbour prediction: empty frame");
  if (!frame.delta_l_m.SameSize(w, h) || !frame.flags.SameSize(w, h)) {
    Bad("neighbour prediction: the frame needs ΔL and flags of its size (enable the accuracy "
        "stage)");
  }
}

// q = 1/d and σ_q² of one frame row into a padded row (NaN where not usable).
void PadRow(int w, const float* d, const float* s, const PixelFlags* flags, float* q, float* vq) {
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  for (int c = 0; c < w; ++c) {
    const float dc = d[c], sc = s[c];
    const bool usable = !flags[c].Any(kRejectMask) && dc >= kMinDistanceM && dc <= kMaxDistanceM &&
                        sc >= kMinDeltaLM && sc <= kMaxDeltaLM;
    const float sq = sc / (dc * dc);
    q[c] = usable ? 1.0f / dc : kNaN;
    vq[c] = usable ? sq * sq : kNaN;
  }
}

// One pair offset's midpoints and weights for a row: for every pixel c, the pair (c + j in the
// row `qa`, c - j in the row `qb`; the pointers already shifted) has midpoint (q_a + q_b) / 2
// and weight 4 / (σ_qa² + σ_qb²), the inverse of the midpoint's variance; weight 0 (midpoint 0)
// where either pixel is not usable.
TOFCAM_HOT_LOOP_WIDE void PairRow(int w, const float* __restrict qa, const float* __restrict va,
                                  const float* __restrict qb, const float* __restrict vb,
                                  float* __restrict mid, float* __restrict weight) {
  for (int c = 0; c < w; ++c) {
    const float a = qa[c], b = qb[c];
    const bool ok = (a == a) & (b == b);
    const float wc = 4.0f / (va[c] + vb[c]);
    const float mc = 0.5f * (a + b);
    weight[c] = ok ? wc : 0.0f;
    mid[c] = ok ? mc : 0.0f;
  }
}

// A pair offset's contribution to a window's sums of weights, weighted midpoints and pairs.
TOFCAM_HOT_LOOP_WIDE void AddPair(int w, const float* __restrict mid,
                                  const float* __restrict weight, float* __restrict sw,
                                  float* __restrict swx, float* __restrict n) {
  for (int c = 0; c < w; ++c) {
    sw[c] += weight[c];
    swx[c] += weight[c] * mid[c];
    n[c] += weight[c] > 0.0f ? 1.0f : 0.0f;
  }
}

// The largest (midpoint - prediction)² / σ_mid² over one pair offset, into `worst` (0 for an
// unusable pair, whose weight is 0).
TOFCAM_HOT_LOOP_WIDE void WorstPair(int w, const float* __restrict mid,
                                    const float* __restrict weight, const float* __restrict p,
                                    float* __restrict worst) {
  for (int c = 0; c < w; ++c) {
    const float dev = mid[c] - p[c];
    const float z2 = dev * dev * weight[c];
    worst[c] = z2 > worst[c] ? z2 : worst[c];
  }
}

// p = swx / sw where sw > 0, else NaN.
TOFCAM_HOT_LOOP_WIDE void Divide(int w, const float* __restrict swx, const float* __restrict sw,
                                 float* __restrict p) {
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  for (int c = 0; c < w; ++c) p[c] = sw[c] > 0.0f ? swx[c] / sw[c] : kNaN;
}

// Where window ρ passes (enough pairs, none beyond k² in squared σ, a positive prediction), its
// prediction in q and weight sum replace what `pq` and `sw` hold.
TOFCAM_HOT_LOOP_WIDE void ChooseWindow(int w, float min_pairs, float k2, const float* __restrict n,
                                       const float* __restrict worst, const float* __restrict p,
                                       const float* __restrict weight_sum, float* __restrict pq,
                                       float* __restrict sw) {
  for (int c = 0; c < w; ++c) {
    const bool pass = (n[c] >= min_pairs) & (worst[c] <= k2) & (p[c] > 0.0f);
    pq[c] = pass ? p[c] : pq[c];
    sw[c] = pass ? weight_sum[c] : sw[c];
  }
}

// In place: q_p and Σ w into p = 1/q_p and σ_p = σ_q p² (first order), σ_q = (Σ w)^-1/2; NaN
// where no window passed (q_p NaN).
TOFCAM_HOT_LOOP_WIDE void FinishRow(int w, float* __restrict pq, float* __restrict sw) {
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  for (int c = 0; c < w; ++c) {
    const float q = pq[c];
    const float pc = 1.0f / q;
    const float sigma = pc * pc / std::sqrt(sw[c]);
    pq[c] = pc;
    sw[c] = q == q ? sigma : kNaN;
  }
}

struct PairOffset {
  int dr, dc, ring;
};

// Each symmetric pair once (dr > 0, or dr = 0 and dc > 0), ring by ring from the centre, in a
// fixed order.
std::vector<PairOffset> PairOffsets(int radius) {
  std::vector<PairOffset> offsets;
  for (int ring = 1; ring <= radius; ++ring) {
    for (int dr = 0; dr <= ring; ++dr) {
      for (int dc = -ring; dc <= ring; ++dc) {
        if (dr == 0 && dc <= 0) continue;
        if (std::max(dr, std::abs(dc)) != ring) continue;
        offsets.push_back({dr, dc, ring});
      }
    }
  }
  return offsets;
}

}  // namespace

void NeighbourPredictionOptions::Validate() const {
  if (!(radius_px >= 1 && radius_px <= kMaxRadius)) {
    Bad("prediction.radius_px = " + std::to_string(radius_px) + " must be in [1, 5]");
  }
  if (!(max_disagreement_sigma > 0.0 && max_disagreement_sigma <= 100.0)) {
    Bad("prediction.max_disagreement_sigma = " + std::to_string(max_disagreement_sigma) +
        " must be in (0, 100]");
  }
  // The largest window (2R + 1)^2 has 2 R (R + 1) pairs; more can never be met.
  const int pairs = radius_px >= 1 && radius_px <= kMaxRadius ? 2 * radius_px * (radius_px + 1) : 0;
  if (!(min_pairs >= 1 && min_pairs <= pairs)) {
    Bad("prediction.min_pairs = " + std::to_string(min_pairs) + " must be in [1, " +
        std::to_string(pairs) + "] (the pairs of a " + std::to_string(2 * radius_px + 1) + "x" +
        std::to_string(2 * radius_px + 1) + " window)");
  }
}

NeighbourPrediction PredictFromNeighbours(const MetricFrame& frame,
                                          const NeighbourPredictionOptions& options) {
  NeighbourPrediction out;
  PredictFromNeighboursInto(frame, options, out);
  return out;
}

void PredictFromNeighboursInto(const MetricFrame& frame, const NeighbourPredictionOptions& options,
                               NeighbourPrediction& out) {
  CheckInput(frame, options);
  const int w = frame.width(), h = frame.height(), R = options.radius_px;
  if (!out.distance_m.SameSize(w, h)) out.distance_m = Image<float>(w, h);
  if (!out.sigma_m.SameSize(w, h)) out.sigma_m = Image<float>(w, h);
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

  // Padded q and σ_q² (R pixels of NaN on every side), so that no pair needs a bounds check.
  const std::size_t pw = static_cast<std::size_t>(w) + 2 * R;
  const std::size_t ph = static_cast<std::size_t>(h) + 2 * R;
  thread_local std::vector<float> q, vq;
  q.assign(pw * ph, kNaN);
  vq.assign(pw * ph, kNaN);
  for (int r = 0; r < h; ++r) {
    const std::size_t o = (static_cast<std::size_t>(r) + R) * pw + R;
    PadRow(w, frame.radial_distance_m.Row(r).data(), frame.delta_l_m.Row(r).data(),
           frame.flags.Row(r).data(), &q[o], &vq[o]);
  }
  const std::vector<PairOffset> offsets = PairOffsets(R);
  // Per ring: the sums of weights, weighted midpoints and pairs; per window: its prediction in q
  // and the worst pair's squared deviation in σ.
  // Rows are done in blocks of columns, so that a block's midpoints and weights (8 bytes a pair
  // and pixel: 48 KiB for 24 pairs of 256 pixels) stay in the cache between the two passes.
  const std::size_t uw = static_cast<std::size_t>(std::min(w, kBlockPixels));
  thread_local std::vector<float> sums, p, worst;
  sums.resize(3 * static_cast<std::size_t>(R) * uw);
  p.resize(static_cast<std::size_t>(R) * uw);
  worst.resize(static_cast<std::size_t>(R) * uw);
  const auto sum = [&](int which, int ring) {  // which: 0 weights, 1 weighted midpoints, 2 pairs
    return &sums[(static_cast<std::size_t>(which) * R + (ring - 1)) * uw];
  };
  const float k2 =
      static_cast<float>(options.max_disagreement_sigma * options.max_disagreement_sigma);
  const auto min_pairs = static_cast<float>(options.min_pairs);

  // Per pair offset, the row's midpoints and weights (computed once, read by both passes).
  thread_local std::vector<float> mids, weights;
  mids.resize(offsets.size() * uw);
  weights.resize(offsets.size() * uw);

  for (int r = 0; r < h; ++r) {
    for (int c0 = 0; c0 < w; c0 += kBlockPixels) {
      const int bw = std::min(kBlockPixels, w - c0);
      std::fill(sums.begin(), sums.end(), 0.0f);
      const auto at = [&](int dr, int dc) {
        return (static_cast<std::size_t>(r) + R + dr) * pw + static_cast<std::size_t>(R + c0 + dc);
      };
      for (std::size_t k = 0; k < offsets.size(); ++k) {
        const PairOffset& o = offsets[k];
        const std::size_t a = at(o.dr, o.dc), b = at(-o.dr, -o.dc);
        PairRow(bw, &q[a], &vq[a], &q[b], &vq[b], &mids[k * uw], &weights[k * uw]);
        AddPair(bw, &mids[k * uw], &weights[k * uw], sum(0, o.ring), sum(1, o.ring),
                sum(2, o.ring));
      }
      // Window ρ holds rings 1..ρ: cumulative sums, innermost ring first, into ring ρ's slots.
      for (int ring = 2; ring <= R; ++ring) {
        for (int which = 0; which < 3; ++which) {
          const float* inner = sum(which, ring - 1);
          float* outer = sum(which, ring);
          for (int c = 0; c < bw; ++c) outer[c] = inner[c] + outer[c];
        }
      }
      for (int ring = 1; ring <= R; ++ring) {
        float* pr = &p[(ring - 1) * uw];
        const float* sw = sum(0, ring);
        const float* swx = sum(1, ring);
        Divide(bw, swx, sw, pr);
        std::fill_n(&worst[(ring - 1) * uw], uw, 0.0f);
      }
      for (std::size_t k = 0; k < offsets.size(); ++k) {
        // A pair of ring k belongs to every window ρ >= k.
        for (int ring = offsets[k].ring; ring <= R; ++ring) {
          WorstPair(bw, &mids[k * uw], &weights[k * uw], &p[(ring - 1) * uw],
                    &worst[(ring - 1) * uw]);
        }
      }
      // The largest window that passes, chosen ring by ring from the innermost (a later pass
      // overrides): its prediction and weight sum; NaN and 0 where none passes.
      float* pd = out.distance_m.Row(r).data() + c0;
      float* ps = out.sigma_m.Row(r).data() + c0;
      std::fill_n(pd, bw, kNaN);
      std::fill_n(ps, bw, 0.0f);
      for (int ring = 1; ring <= R; ++ring) {
        ChooseWindow(bw, min_pairs, k2, sum(2, ring), &worst[(ring - 1) * uw], &p[(ring - 1) * uw],
                     sum(0, ring), pd, ps);
      }
      FinishRow(bw, pd, ps);
    }
  }
}

double ReadingPosterior::ReadingRmsErrorM() const {
  return std::sqrt(mean_error_m * mean_error_m + variance_m2);
}

Image<float> CombineWithPrediction(const MetricFrame& frame,
                                   const NeighbourPrediction& prediction) {
  Image<float> out;
  CombineWithPredictionInto(frame, prediction, out);
  return out;
}

void CombineWithPredictionInto(const MetricFrame& frame, const NeighbourPrediction& prediction,
                               Image<float>& out) {
  const int w = frame.width(), h = frame.height();
  if (!frame.delta_l_m.SameSize(w, h) || !frame.flags.SameSize(w, h)) {
    Bad("combine with prediction: the frame needs ΔL and flags of its size");
  }
  // `out` may be the frame's distance image (read and written pixel by pixel), but no other
  // channel that the loop reads.
  if (&out == &frame.delta_l_m || &out == &prediction.distance_m || &out == &prediction.sigma_m) {
    Bad("combine with prediction: `out` must be the frame's distance image or an image of its "
        "own, not ΔL or the prediction");
  }
  if (!prediction.distance_m.SameSize(w, h) || !prediction.sigma_m.SameSize(w, h)) {
    throw Error(ErrorCode::kMismatch, "combine with prediction: the prediction is " +
                                          std::to_string(prediction.distance_m.width()) + "x" +
                                          std::to_string(prediction.distance_m.height()) +
                                          ", the frame " + std::to_string(w) + "x" +
                                          std::to_string(h));
  }
  if (&out != &frame.radial_distance_m) {
    if (!out.SameSize(w, h)) out = Image<float>(w, h);
    std::copy(frame.radial_distance_m.data(),
              frame.radial_distance_m.data() + frame.radial_distance_m.size(), out.data());
  }
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (frame.flags[i].Any(kRejectMask)) continue;
    const ReadingPosterior post =
        PosteriorOfReading(frame.radial_distance_m[i], frame.delta_l_m[i], prediction.distance_m[i],
                           prediction.sigma_m[i]);
    if (std::isfinite(post.mean_error_m)) {
      out[i] = static_cast<float>(frame.radial_distance_m[i] - post.mean_error_m);
    }
  }
}

}  // namespace tofcam

#pragma once
// Saturation of one lock-in pixel's four storage sites (docs/simulator.md, pipeline step 7).
// Internal to tofcam::sim; a header of its own so that tests can check it on hand-computed
// charges.

#include <algorithm>

namespace tofcam::sim::internal {

/// Clips the four tap charges `n` (electrons) at `full_well` and lets `keep_share` (in [0, 1]) of
/// the excess spill over into the pixel's sites that still have room, filled evenly (water
/// filling: each round fills at least one more site, so four rounds always suffice). Returns the
/// charge that does not stay in the pixel (>= 0): the rest of the excess plus what found no room.
/// Charge is conserved: the sum of `n` plus the return value equals the sum before.
inline float OverflowPixel(float n[4], float full_well, float keep_share) {
  float excess = 0.0f;
  for (int k = 0; k < 4; ++k) {
    if (n[k] > full_well) {
      excess += n[k] - full_well;
      n[k] = full_well;
    }
  }
  if (!(excess > 0.0f)) return 0.0f;
  float keep = keep_share * excess;
  for (int round = 0; round < 4 && keep > 0.0f; ++round) {
    int room = 0;
    for (int k = 0; k < 4; ++k) room += n[k] < full_well;
    if (room == 0) break;
    const float share = keep / static_cast<float>(room);
    for (int k = 0; k < 4; ++k) {
      if (!(n[k] < full_well)) continue;
      const float add = std::min(share, full_well - n[k]);
      n[k] += add;
      keep -= add;
    }
  }
  return (1.0f - keep_share) * excess + std::max(keep, 0.0f);
}

}  // namespace tofcam::sim::internal

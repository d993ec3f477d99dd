#pragma once
// Shared by the simulator's stages (internal to tofcam::sim): the function-multiversioning
// attribute of the hot row loops and the "no hit" distance.

#include <limits>

namespace tofcam::sim::internal {

inline constexpr float kInf = std::numeric_limits<float>::infinity();

}  // namespace tofcam::sim::internal

// The hot row loops below are compiled for the x86-64 baseline (SSE2), AVX2 and x86-64-v4
// (AVX-512), and the dynamic loader picks one for the CPU (GCC/Clang function multiversioning);
// the library stays built for the baseline. Every clone does the same IEEE operations in the same
// order (the simulator is built with -ffp-contract=off: the v4 target has FMA, and GCC contracts
// in C++ by default; the loops have no floating-point reductions, whose order vector width could
// change), so results do not depend on the CPU (simulated_camera_golden_test). Not under
// AddressSanitizer, whose run time starts after the loader has called the ifunc resolvers that
// pick the clones.
#if defined(__SANITIZE_ADDRESS__)
#define TOFCAM_SIM_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define TOFCAM_SIM_ASAN 1
#endif
#endif
// TOFCAM_SIM_LOOP marks such a loop: out of line (see below) and, where available, cloned.
// Clang refuses noinline together with target_clones; a clone is called through its ifunc
// resolver and never inlined anyway, so clang gets the clones alone. The x86-64-v4 clone took 5 %
// off a moving SR-2 frame and 7 % off a 640x480 one on a Zen 5 (sim_profile, three alternated
// runs; docs/benchmarks.md).
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(TOFCAM_SIM_ASAN)
#if defined(__clang__)
#define TOFCAM_SIM_LOOP __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define TOFCAM_SIM_LOOP \
  [[gnu::noinline]] __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#endif
#else
#define TOFCAM_SIM_LOOP [[gnu::noinline]]
#endif

// The loops below take __restrict pointers: without them GCC needs more run-time alias checks
// than it is willing to emit and leaves them scalar. They are kept out of line (noinline),
// because GCC forgets the __restrict of parameters once a function is inlined into a caller.

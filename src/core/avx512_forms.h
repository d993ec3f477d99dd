#pragma once
// Run-time choice between a stage's AVX-512 form (written with intrinsics, 16 lanes) and its
// portable loops (baseline or TOFCAM_HOT_LOOP clones). Internal to tofcam; shared by the
// flying-pixel and Weingarten filters and false colour.
//
// TOFCAM_AVX512_FORMS: the AVX-512 forms are compiled (x86-64, GCC or clang), except under
// AddressSanitizer (TOFCAM_NO_CLONES, src/filters/hot_loop.h), so that the sanitizer build checks
// the portable loops the AVX-512 forms are tested against.

#include <atomic>

#include "../filters/hot_loop.h"

#if defined(__x86_64__) && defined(__GNUC__) && !defined(TOFCAM_NO_CLONES)
#define TOFCAM_AVX512_FORMS 1
#endif

namespace tofcam::internal {

/// Whether this CPU has the AVX-512 subsets the forms use (F, BW, VL, DQ); decided once.
[[nodiscard]] bool CpuHasAvx512();

/// Set by UsePortableFormsForTesting.
extern std::atomic<bool> portable_forms_only;

/// Whether the stages run their AVX-512 forms: compiled in, the CPU has them, and no test asked
/// for the portable forms. Inline (called per row): a guard check and a relaxed load.
[[nodiscard]] inline bool UseAvx512Forms() {
  static const bool has = CpuHasAvx512();
  return has && !portable_forms_only.load(std::memory_order_relaxed);
}

/// Tests only: with true, every stage with an AVX-512 form runs its portable loops even on an
/// AVX-512 CPU, so a test can compare both forms on one machine. Process-wide; not meant to be
/// flipped while another thread runs a stage.
void UsePortableFormsForTesting(bool portable);

}  // namespace tofcam::internal

#pragma once
// Run-time choice between a stage's AVX-512 form (written with intrinsics, 16 lanes) and its
// portable loops (baseline or TOFCAM_HOT_LOOP clones). Internal to tofcam; shared by the
// flying-pixel and Weingarten filters, false colour and the calibration's table kernel.
//
// TOFCAM_AVX512_FORMS: the AVX-512 forms are compiled (x86-64, GCC or clang), except under
// AddressSanitizer (TOFCAM_NO_CLONES, src/filters/hot_loop.h), so that the sanitizer build checks
// the portable loops the AVX-512 forms are tested against.

#include <atomic>

#include "../filters/hot_loop.h"

#if defined(__x86_64__) && defined(__GNUC__) && !defined(TOFCAM_NO_CLONES)
#define TOFCAM_AVX512_FORMS 1
// The subsets every form may use (CpuHasAvx512 checks all four).
#define TOFCAM_AVX512_TARGET __attribute__((target("avx512f,avx512bw,avx512vl,avx512dq")))
#define TOFCAM_AVX512_INLINE \
  __attribute__((target("avx512f,avx512bw,avx512vl,avx512dq"), always_inline)) inline
// GCC 12's AVX-512 headers start some intrinsics from _mm512_undefined_*(), which
// -Wmaybe-uninitialized reports (GCC bug 105593); no form reads an undefined value.
#if defined(__clang__)
#define TOFCAM_AVX512_DIAGNOSTICS_BEGIN
#define TOFCAM_AVX512_DIAGNOSTICS_END
#else
#define TOFCAM_AVX512_DIAGNOSTICS_BEGIN \
  _Pragma("GCC diagnostic push") _Pragma("GCC diagnostic ignored \"-Wmaybe-uninitialized\"")
#define TOFCAM_AVX512_DIAGNOSTICS_END _Pragma("GCC diagnostic pop")
#endif
#endif

namespace tofcam::internal {

/// Whether this CPU has the AVX-512 subsets the forms use (F, BW, VL, DQ; libgcc's check
/// includes the operating system's support for the registers); decided once. False where the
/// forms are not compiled.
[[nodiscard]] bool CpuHasAvx512();

namespace detail {
/// Set by UsePortableFormsForTesting; read by UseAvx512Forms.
extern std::atomic<bool> portable_forms_only;
}  // namespace detail

/// Whether the stages run their AVX-512 forms: compiled in, the CPU has them, and no test asked
/// for the portable forms. Inline (called per row): a guard check and a relaxed load.
[[nodiscard]] inline bool UseAvx512Forms() {
  static const bool has = CpuHasAvx512();
  return has && !detail::portable_forms_only.load(std::memory_order_relaxed);
}

/// Tests and benchmarks only: with true, every stage with an AVX-512 form runs its portable loops
/// even on an AVX-512 CPU, so a test can compare both forms on one machine. Process-wide; not meant
/// to be flipped while another thread runs a stage (either form gives the same values, so a flip
/// only changes which one runs).
void UsePortableFormsForTesting(bool portable);

/// Tests and benchmarks only: UsePortableFormsForTesting(portable) for the guard's lifetime, then
/// back to the default, also when the code under test throws.
class PortableFormsForTesting {
 public:
  explicit PortableFormsForTesting(bool portable) { UsePortableFormsForTesting(portable); }
  ~PortableFormsForTesting() { UsePortableFormsForTesting(false); }
  PortableFormsForTesting(const PortableFormsForTesting&) = delete;
  PortableFormsForTesting& operator=(const PortableFormsForTesting&) = delete;
};

}  // namespace tofcam::internal

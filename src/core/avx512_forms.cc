#include "avx512_forms.h"

namespace tofcam::internal {

namespace detail {
std::atomic<bool> portable_forms_only{false};
}  // namespace detail

bool CpuHasAvx512() {
#if defined(TOFCAM_AVX512_FORMS)
  static const bool has = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
           __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq");
  }();
  return has;
#else
  return false;
#endif
}

void UsePortableFormsForTesting(bool portable) {
  detail::portable_forms_only.store(portable, std::memory_order_relaxed);
}

}  // namespace tofcam::internal

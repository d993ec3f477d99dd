#include "avx512_forms.h"

#include <atomic>

namespace tofcam::internal {
namespace {

std::atomic<bool> portable_only{false};

}  // namespace

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

bool UseAvx512Forms() { return CpuHasAvx512() && !portable_only.load(std::memory_order_relaxed); }

void UsePortableFormsForTesting(bool portable) {
  portable_only.store(portable, std::memory_order_relaxed);
}

}  // namespace tofcam::internal

#pragma once

// Portable fixed-width vectors (GCC / clang vector extensions) for reductions GCC will not
// vectorise by itself (double sums it may not reorder): 8 float lanes, two 4-lane double halves.
// They compile to SSE2 in the baseline and to AVX2 in a TOFCAM_HOT_LOOP's AVX2 clone, and the
// lane order is explicit, so the result is the same on every CPU.
//
// Including this header silences -Wpsabi for the translation unit: the helpers are always
// inlined into the loops, so no 32-byte vector is ever passed by value across a call and GCC's
// note about the AVX calling convention does not apply.

#include <cstdint>
#include <cstring>

#pragma GCC diagnostic ignored "-Wpsabi"

namespace tofcam::simd {

typedef float F8 __attribute__((vector_size(32)));
typedef float F4 __attribute__((vector_size(16)));
typedef double D4 __attribute__((vector_size(32)));
typedef std::int32_t I8 __attribute__((vector_size(32)));
typedef std::uint16_t U8 __attribute__((vector_size(16)));

[[gnu::always_inline]] inline F8 LoadF8(const float* p) {
  F8 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
[[gnu::always_inline]] inline I8 LoadFlags8(
    const void* p) {  // 8 x uint16 (PixelFlags), zero-extended
  U8 v;
  std::memcpy(&v, p, sizeof v);
  return __builtin_convertvector(v, I8);
}
[[gnu::always_inline]] inline F8 Select(I8 mask, F8 v) {
  return reinterpret_cast<F8>(mask & reinterpret_cast<I8>(v));
}
[[gnu::always_inline]] inline I8 AbsBits(F8 v) { return reinterpret_cast<I8>(v) & 0x7fffffff; }
[[gnu::always_inline]] inline D4 Low(F8 v) {
  return __builtin_convertvector(__builtin_shufflevector(v, v, 0, 1, 2, 3), D4);
}
[[gnu::always_inline]] inline D4 High(F8 v) {
  return __builtin_convertvector(__builtin_shufflevector(v, v, 4, 5, 6, 7), D4);
}

}  // namespace tofcam::simd

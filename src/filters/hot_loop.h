#pragma once
// TOFCAM_HOT_LOOP: compile a hot loop twice, for AVX2 and for the baseline, and pick one at load
// time (GCC / clang function multiversioning through an ELF ifunc), so one binary runs
// everywhere and uses 8-wide vectors where the CPU has them. Off under AddressSanitizer and
// outside x86-64 Linux. Shared by the library's hot loops (src/filters, src/cloud, src/color,
// src/calibration, src/pipeline, src/pan, ...) and by src/core/avx512_forms.h.

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define TOFCAM_NO_CLONES 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__)
#define TOFCAM_NO_CLONES 1
#endif

#if defined(__x86_64__) && defined(__linux__) && defined(__GNUC__) && !defined(TOFCAM_NO_CLONES)
#define TOFCAM_HOT_LOOP __attribute__((target_clones("avx2", "default")))
// A third clone for AVX-512 CPUs (x86-64-v4: 16 float lanes, 32 vector registers, FMA), only for
// loops measured to gain from it (long per-element arithmetic that spills with 16 registers) and
// whose results do not depend on fused multiply-adds.
#define TOFCAM_HOT_LOOP_WIDE __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define TOFCAM_HOT_LOOP
#define TOFCAM_HOT_LOOP_WIDE
#endif

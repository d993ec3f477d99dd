# Per-target compile settings; tofcam sets no global flags.

# The linker of every target set up here (what links: the tests, the CLI, the Python module, the
# benchmarks and tools): -fuse-ld=<TOFCAM_LINKER>, e.g. lld; empty leaves the compiler's default.
# lld cannot link GCC's LTO objects: with CMAKE_INTERPROCEDURAL_OPTIMIZATION, configure with
# -DTOFCAM_LINKER= (`make LINKER=`). `make` picks lld when
# it is installed: it linked a sanitizer-built test in 1.0 s against GNU ld's 2.4 s, and a build
# links about 90 executables (the CI run must stay under 30 minutes). Private to each target, so
# nothing of it reaches the exported targets.
set(TOFCAM_LINKER "" CACHE STRING "Linker for tofcam's executables and modules (-fuse-ld=)")
if(TOFCAM_LINKER)
  include(CheckLinkerFlag)
  # Checked again at every configure, so that installing the linker after a failed check helps.
  unset(TOFCAM_LINKER_WORKS_${TOFCAM_LINKER} CACHE)
  check_linker_flag(CXX "-fuse-ld=${TOFCAM_LINKER}" TOFCAM_LINKER_WORKS_${TOFCAM_LINKER})
  if(NOT TOFCAM_LINKER_WORKS_${TOFCAM_LINKER})
    message(FATAL_ERROR "TOFCAM_LINKER=${TOFCAM_LINKER}: the compiler cannot link with "
                        "-fuse-ld=${TOFCAM_LINKER} (install it, e.g. apt-get install lld, or "
                        "configure with -DTOFCAM_LINKER=)")
  endif()
endif()

function(tofcam_target_options target)
  target_compile_features(${target} PUBLIC cxx_std_20)
  set_target_properties(${target} PROPERTIES CXX_EXTENSIONS OFF POSITION_INDEPENDENT_CODE ON)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic
                                           $<$<CXX_COMPILER_ID:GNU>:-Wshadow=local>
                                           # GCC 12 false positive in std::string concatenation
                                           # at -O2 (GCC bug 105651).
                                           $<$<CXX_COMPILER_ID:GNU>:-Wno-restrict>)
  if(TOFCAM_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  if(TOFCAM_LINKER)
    target_link_options(${target} PRIVATE -fuse-ld=${TOFCAM_LINKER})
  endif()
  if(TOFCAM_SANITIZE)
    target_compile_options(${target} PRIVATE -fsanitize=address,undefined -fno-omit-frame-pointer
                                             -fno-sanitize-recover=undefined)
    target_link_options(${target} PUBLIC -fsanitize=address,undefined)
  endif()
endfunction()

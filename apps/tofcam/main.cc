// tofcam: command-line entry point.
#include <hdf5.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "commands.h"
#include "tofcam/core/error.h"
#include "tofcam/version.h"

namespace tofcam::cli {

std::map<std::string, CommandSetup>& CommandRegistry() {
  static std::map<std::string, CommandSetup> registry;
  return registry;
}

bool RegisterCommand(const std::string& name, CommandSetup setup) {
  CommandRegistry().emplace(name, std::move(setup));
  return true;
}

}  // namespace tofcam::cli

namespace {

// Keep freed memory in the process. Frames and stage outputs of a few MB are allocated and freed
// at camera rate; by default glibc serves blocks above 128 KB with mmap, or (after its dynamic
// threshold rises) returns the freed top of the heap, so every frame's images are page-faulted
// in and zero-filled by the kernel again: `tofcam run` on the simulated 640x480 camera took
// 2.1 times as long (docs/benchmarks.md). Thresholds: blocks below 32 MiB from the heap (glibc's
// largest mmap threshold); the free top of a heap is returned to the kernel only beyond 512 MiB.
// Library users get the same with GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:
// glibc.malloc.trim_threshold=536870912 (one string; docs/python.md).
void KeepFreedMemory() {
#if defined(__GLIBC__)
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 512 << 20);
#endif
}

int Run(int argc, char** argv) {
  KeepFreedMemory();
  CLI::App app{"tofcam: time-of-flight cameras for mobile robots"};
  try {
    app.set_version_flag("--version", tofcam::kVersionString);
    app.require_subcommand(1);
    for (auto& [name, setup] : tofcam::cli::CommandRegistry()) setup(app);
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const tofcam::Error& e) {
    std::fprintf(stderr, "tofcam: error (%s): %s\n", std::string(ErrorCodeName(e.code())).c_str(),
                 e.what());
    return tofcam::ExitStatus(e.code());
  }
  return 0;
}

}  // namespace

// Everything that can throw, including the construction of the CLI11 app, runs inside Run(), so
// no exception escapes main (clang-tidy bugprone-exception-escape) and the user always gets a
// one-line reason and a non-zero status.
int main(int argc, char** argv) {
  // libhdf5 closes what is still open from an atexit handler. After a reader gave up on a
  // damaged recording, a file libhdf5 itself cannot close makes that handler print "HDF5:
  // infinite loop closing library" and a line of its interfaces after tofcam's one-line error.
  // Every tofcam file is closed by its owner before main returns (a recording's frames are
  // committed one by one), so the handler has nothing to do: it is not registered. Before any
  // other HDF5 call, so here, in the program, never in the library (a host program's own HDF5
  // files need it).
  H5dont_atexit();
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tofcam: internal error: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "tofcam: internal error: unknown exception\n");
  }
  return tofcam::ExitStatus(tofcam::ErrorCode::kInternal);
}

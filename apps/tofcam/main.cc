// tofcam: command-line entry point.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>

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

int Run(int argc, char** argv) {
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
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tofcam: internal error: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "tofcam: internal error: unknown exception\n");
  }
  return tofcam::ExitStatus(tofcam::ErrorCode::kInternal);
}

#pragma once
// Subcommand registration. Each subcommand lives in its own <name>_command.cc and exposes one
// Setup function that adds itself to the app; main.cc calls them all. A callback reports
// failures by throwing tofcam::Error; main turns that into a one-line message and exit status.

#include <CLI/CLI.hpp>

namespace tofcam::cli {

void SetupInfoCommand(CLI::App& app);

}  // namespace tofcam::cli

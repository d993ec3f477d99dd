#pragma once
// Subcommand registration. Each subcommand lives in its own <name>_command.cc and registers a
// setup function with TOFCAM_REGISTER_COMMAND; main.cc adds them all in name order. A callback
// reports failures by throwing tofcam::Error; main turns that into a one-line message and exit
// status. Long-running commands print progress to stderr.

#include <CLI/CLI.hpp>
#include <functional>
#include <map>
#include <string>

namespace tofcam::cli {

using CommandSetup = std::function<void(CLI::App& app)>;

/// All registered commands by name.
std::map<std::string, CommandSetup>& CommandRegistry();

/// Registers a subcommand; returns true so it can initialise a namespace-scope constant.
bool RegisterCommand(const std::string& name, CommandSetup setup);

/// For unsigned options (seeds): CLI11 reads "-1" into an unsigned field as 2^64 - 1.
inline const CLI::Validator kNonNegative(
    [](std::string& input) {
      return input.find('-') == std::string::npos ? std::string()
                                                  : "'" + input + "' must not be negative";
    },
    "UINT");

/// `--ros2-domain N` (0..232) for a command that opens camera sources: the DDS domain of a
/// `ros2:` source whose spec names none (`?domain=`), default 0. Every command with --camera
/// takes it, as the sources' help line says.
inline CLI::Option* AddRos2DomainOption(CLI::App* sub, int& domain) {
  return sub
      ->add_option("--ros2-domain", domain,
                   "DDS domain (ROS_DOMAIN_ID), 0..232, of a ros2: camera source")
      ->check(CLI::Range(0, 232))
      ->capture_default_str();
}

}  // namespace tofcam::cli

#define TOFCAM_REGISTER_COMMAND(name, setup)                      \
  [[maybe_unused]] static const bool tofcam_registered_command_ = \
      ::tofcam::cli::RegisterCommand(name, setup)

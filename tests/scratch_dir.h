#pragma once
// A scratch folder per test process under the system's temp directory, removed when the test
// program ends (ctest runs every test in its own process, so nothing is left behind).

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

namespace tofcam::testing {

/// `<temp>/<prefix><pid>`, created on first use and removed at exit with everything in it.
inline std::filesystem::path ScratchDir(const std::string& prefix) {
  struct Cleanup : ::testing::Environment {
    explicit Cleanup(std::filesystem::path d) : dir(std::move(d)) {}
    void TearDown() override {
      std::error_code ec;
      std::filesystem::remove_all(dir, ec);
    }
    std::filesystem::path dir;
  };
  static const std::filesystem::path dir = [&] {
    const std::filesystem::path d =
        std::filesystem::temp_directory_path() / (prefix + std::to_string(::getpid()));
    ::testing::AddGlobalTestEnvironment(new Cleanup(d));  // gtest owns it
    return d;
  }();
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace tofcam::testing

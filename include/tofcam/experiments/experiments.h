#pragma once
/// \file
/// Reproductions of the paper's experiments (May et al., IROS 2006, figs. 2-11) on the simulated
/// SR-2 against ground truth, plus controller and filter comparisons (issue 5). Each experiment
/// returns tables (written as CSV), false-colour images and a markdown section; the numbers are
/// computed here, scripts/plot_experiments.py only draws the CSVs. See docs/experiments.md.

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "tofcam/core/image.h"
#include "tofcam/core/rgb.h"

namespace tofcam::experiments {

/// Run settings shared by all experiments. Everything is seeded: the same options give the same
/// numbers (timings excepted).
struct ExperimentOptions {
  std::uint64_t seed = 1;  ///< Simulator noise seed, any value.
  int threads = 2;         ///< Simulator threads, 1..64 (results do not depend on it).
  /// Work factor in (0, 1]: 1 is the full run of `make experiments`; tests use ~0.25, which
  /// coarsens register sweeps and shortens sequences (never below a few frames per setting).
  double effort = 1.0;
  /// Folder with the ifm O3D303 recording `o3d3xx.h5` (real-data experiment).
  std::filesystem::path real_data_dir = "tests/data/real/ifm_o3d303";

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// A table; cells are already formatted. Written as `<file>.csv`.
struct Table {
  std::string file;  ///< CSV base name, e.g. "fig3_sweep".
  std::vector<std::string> columns;
  std::vector<std::vector<std::string>> rows;
  bool in_markdown = false;  ///< Also printed in results.md (keep such tables short).
};

/// A false-colour image written by the C++ side as `<file>.png`.
struct NamedImage {
  std::string file;
  std::string caption;
  Image<Rgb8> image;
};

struct ExperimentResult {
  std::string name;   ///< As in ExperimentNames().
  std::string title;  ///< Section heading.
  std::vector<Table> tables;
  std::vector<NamedImage> images;
  /// PNGs the plot script draws from the CSVs (base names, linked from the markdown).
  std::vector<std::string> plots;
  /// Markdown prose: findings, comparison with the paper, deviations and why.
  std::string text;
  /// Key numbers by name (what the tests assert and the prose quotes).
  std::map<std::string, double> metrics;
  double seconds = 0.0;  ///< Wall time of the run.
};

/// "fig2", "fig3", "fig5", "fig6-7", "fig8-9", "fig10-11", "mirror", "calibration",
/// "controllers", "filters", "real-data", "beyond" (issue 18: the methods beyond the paper), in
/// that order.
[[nodiscard]] std::vector<std::string> ExperimentNames();

/// Runs one experiment. Throws Error(kNotFound) listing the names for an unknown name,
/// Error(kInvalidArgument) for bad options, and the errors of the simulator and importers (e.g.
/// kNotFound when the real-data file is missing).
[[nodiscard]] ExperimentResult RunExperiment(const std::string& name,
                                             const ExperimentOptions& options);

/// Writes the tables as CSV and the images as PNG into `dir` (created), atomically per file.
/// Throws Error(kIo) when a file cannot be written.
void WriteExperimentFiles(const ExperimentResult& result, const std::filesystem::path& dir);

/// The markdown section of one experiment; image links point to `image_prefix + file + ".png"`.
[[nodiscard]] std::string ExperimentMarkdown(const ExperimentResult& result,
                                             const std::string& image_prefix);

/// The opening of results.md: title, set-up and what every table depends on, from the measured
/// metrics of `results` (notes whose experiments did not run are left out).
[[nodiscard]] std::string ResultsPreamble(const std::vector<ExperimentResult>& results,
                                          const ExperimentOptions& options);

}  // namespace tofcam::experiments

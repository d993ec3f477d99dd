// `tofcam experiment <name>|all --out DIR`: reproduces the paper's experiments on the simulated
// SR-2 (issue 5; docs/experiments.md). Writes per experiment its CSV tables and false-colour
// PNGs into DIR, and DIR/results.md with every section (image links under --image-prefix).
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "commands.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/experiments/experiments.h"

namespace tofcam::cli {
namespace {

struct ExperimentCommandOptions {
  std::string name;
  std::string out = "out/experiments";
  std::string image_prefix = "results/";
  std::string real_data_dir;
  experiments::ExperimentOptions run;
};

void RunExperimentCommand(const ExperimentCommandOptions& o) {
  std::vector<std::string> names;
  if (o.name == "all") {
    names = experiments::ExperimentNames();
  } else {
    names.push_back(o.name);
  }
  experiments::ExperimentOptions run = o.run;
  if (!o.real_data_dir.empty()) {
    run.real_data_dir = o.real_data_dir;
  } else {
    run.real_data_dir = std::filesystem::path(TOFCAM_SOURCE_DIR) / "tests/data/real/ifm_o3d303";
  }
  run.Validate();
  std::string sections;
  std::vector<experiments::ExperimentResult> results;
  double total_s = 0;
  for (const std::string& name : names) {
    std::fprintf(stderr, "experiment %s ...\n", name.c_str());
    const experiments::ExperimentResult result = experiments::RunExperiment(name, run);
    experiments::WriteExperimentFiles(result, o.out);
    sections += experiments::ExperimentMarkdown(result, o.image_prefix);
    total_s += result.seconds;
    std::printf("%-12s %6.1f s  %zu table(s), %zu image(s)\n", name.c_str(), result.seconds,
                result.tables.size(), result.images.size());
    std::fflush(stdout);
    // Keep the metrics for the preamble, not the images and tables.
    experiments::ExperimentResult kept;
    kept.name = result.name;
    kept.metrics = result.metrics;
    results.push_back(std::move(kept));
  }
  std::string markdown = experiments::ResultsPreamble(results, run) + sections;
  char total[64];
  std::snprintf(total, sizeof total, "%.0f", total_s);
  markdown += "Total run time of these experiments: " + std::string(total) +
              " s on the shared 2-core machine.\n";
  const std::string md_name = o.name == "all" ? "results.md" : o.name + ".md";
  WriteFileAtomically(std::filesystem::path(o.out) / md_name, markdown);
  std::printf("wrote %s/%s\n", o.out.c_str(), md_name.c_str());
}

void SetupExperimentCommand(CLI::App& app) {
  auto opts = std::make_shared<ExperimentCommandOptions>();
  CLI::App* sub = app.add_subcommand(
      "experiment", "Reproduce the paper's experiments against ground truth (CSV, PNG, markdown)");
  std::string names = "all";
  for (const std::string& n : experiments::ExperimentNames()) names += "|" + n;
  sub->add_option("name", opts->name, names)->required();
  sub->add_option("--out", opts->out, "Output folder")->capture_default_str();
  sub->add_option("--seed", opts->run.seed, "Simulator seed")
      ->check(kNonNegative)
      ->capture_default_str();
  sub->add_option("--threads", opts->run.threads, "Simulator threads, 1..64")
      ->capture_default_str();
  sub->add_option("--effort", opts->run.effort,
                  "Work factor in (0, 1]: fewer frames and coarser sweeps below 1")
      ->capture_default_str();
  sub->add_option("--image-prefix", opts->image_prefix, "Prefix of image links in the markdown")
      ->capture_default_str();
  sub->add_option("--real-data-dir", opts->real_data_dir,
                  "Folder with o3d3xx.h5 (default: the repository's tests/data/real/ifm_o3d303)");
  sub->callback([opts] { RunExperimentCommand(*opts); });
}

TOFCAM_REGISTER_COMMAND("experiment", SetupExperimentCommand);

}  // namespace
}  // namespace tofcam::cli

// The registry of the paper's experiments and their output files. Each experiment lives in its
// own file (fig2.cc ... real_data.cc), helpers shared by several in experiment_common.{h,cc}.
// Every number is computed from simulator frames processed by the library's own stages; nothing
// here models physics. See docs/experiments.md.
#include "tofcam/experiments/experiments.h"

#include "experiment_common.h"

namespace tofcam::experiments {

using internal::Clock;
using internal::F;
using internal::kNaN;
using internal::Mm;
namespace fs = std::filesystem;

void ExperimentOptions::Validate() const {
  if (threads < 1 || threads > 64) {
    throw Error(ErrorCode::kInvalidArgument,
                "experiment threads must be in 1..64, got " + std::to_string(threads));
  }
  if (!(effort > 0.0 && effort <= 1.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "experiment effort must be in (0, 1], got " + std::to_string(effort));
  }
}

std::vector<std::string> ExperimentNames() {
  return {"fig2",   "fig3",        "fig5",        "fig6-7",  "fig8-9",    "fig10-11",
          "mirror", "calibration", "controllers", "filters", "real-data", "beyond"};
}

ExperimentResult RunExperiment(const std::string& name, const ExperimentOptions& options) {
  options.Validate();
  static const std::map<std::string, std::function<ExperimentResult(const ExperimentOptions&)>>
      kRunners = {{"fig2", internal::Fig2},
                  {"fig3", internal::Fig3},
                  {"fig5", internal::Fig5},
                  {"fig6-7", internal::Fig67},
                  {"fig8-9", internal::Fig89},
                  {"fig10-11", internal::Fig1011},
                  {"mirror", internal::Mirror},
                  {"calibration", internal::Calibration},
                  {"controllers", internal::Controllers},
                  {"filters", internal::Filters},
                  {"real-data", internal::RealData},
                  {"beyond", internal::Beyond}};
  const auto it = kRunners.find(name);
  if (it == kRunners.end()) {
    std::string known;
    for (const std::string& n : ExperimentNames()) known += (known.empty() ? "" : ", ") + n;
    throw Error(ErrorCode::kNotFound, "unknown experiment '" + name + "' (known: " + known + ")");
  }
  const Clock::time_point start = Clock::now();
  ExperimentResult result = it->second(options);
  result.name = name;
  result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return result;
}

void WriteExperimentFiles(const ExperimentResult& result, const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw Error(ErrorCode::kIo, "cannot create " + dir.string() + ": " + ec.message());
  // RFC 4180: a cell with a comma, quote or line break is quoted, quotes doubled (labels such
  // as "k 8, std_mul 0.5" contain commas).
  const auto cell = [](const std::string& v) {
    if (v.find_first_of(",\"\n") == std::string::npos) return v;
    std::string q = "\"";
    for (char ch : v) q += ch == '"' ? std::string("\"\"") : std::string(1, ch);
    return q + "\"";
  };
  for (const Table& t : result.tables) {
    std::string csv;
    for (std::size_t c = 0; c < t.columns.size(); ++c) csv += (c ? "," : "") + cell(t.columns[c]);
    csv += '\n';
    for (const auto& row : t.rows) {
      for (std::size_t c = 0; c < row.size(); ++c) csv += (c ? "," : "") + cell(row[c]);
      csv += '\n';
    }
    WriteFileAtomically(dir / (t.file + ".csv"), csv);
  }
  for (const NamedImage& image : result.images)
    WritePngRgb8(dir / (image.file + ".png"), image.image);
}

std::string ExperimentMarkdown(const ExperimentResult& result, const std::string& image_prefix) {
  std::ostringstream md;
  md << "## " << result.title << " (`" << result.name << "`)\n\n";
  if (!result.images.empty()) {
    md << "|";
    for (const NamedImage& image : result.images) md << " " << image.caption << " |";
    md << "\n|";
    for (std::size_t k = 0; k < result.images.size(); ++k) md << "---|";
    md << "\n|";
    for (const NamedImage& image : result.images) {
      md << " ![" << image.caption << "](" << image_prefix << image.file << ".png) |";
    }
    md << "\n\n";
  }
  for (const std::string& plot : result.plots) {
    md << "![" << plot << "](" << image_prefix << plot << ".png)\n\n";
  }
  // A "|" inside a cell would end it (e.g. "|Ī-I_A|"): escaped as "\|".
  const auto cell = [](const std::string& v) {
    std::string out;
    for (char ch : v) out += ch == '|' ? std::string("\\|") : std::string(1, ch);
    return out;
  };
  for (const Table& t : result.tables) {
    if (!t.in_markdown) continue;
    md << "|";
    for (const std::string& c : t.columns) md << " " << cell(c) << " |";
    md << "\n|";
    for (std::size_t k = 0; k < t.columns.size(); ++k) md << "---|";
    md << "\n";
    for (const auto& row : t.rows) {
      md << "|";
      for (const std::string& c : row) md << " " << cell(c) << " |";
      md << "\n";
    }
    md << "\n";
  }
  md << result.text << "\n";
  std::vector<std::string> csvs;
  for (const Table& t : result.tables) csvs.push_back("`" + t.file + ".csv`");
  md << "Data: ";
  for (std::size_t k = 0; k < csvs.size(); ++k) md << (k ? ", " : "") << csvs[k];
  char seconds[32];
  std::snprintf(seconds, sizeof seconds, "%.1f", result.seconds);
  md << " (in `out/experiments/`); run time " << seconds << " s.\n\n";
  return md.str();
}

std::string ResultsPreamble(const std::vector<ExperimentResult>& results,
                            const ExperimentOptions& options) {
  const auto metric = [&](const std::string& experiment, const std::string& key) {
    for (const ExperimentResult& r : results) {
      if (r.name != experiment) continue;
      const auto it = r.metrics.find(key);
      if (it != r.metrics.end()) return it->second;
    }
    return kNaN;
  };
  std::ostringstream md;
  md << "# Results: the paper's experiments against ground truth\n\n"
        "Generated by `make experiments` (`tofcam experiment all --out out/experiments`, then "
        "`scripts/plot_experiments.py`); do not edit by hand. Simulated SR-2 "
        "(docs/simulator.md), seed "
     << options.seed
     << ". Every frame is calibrated with the shared calibration, the paper's per-pixel offsets "
        "(eq. 1, white wall at 2 m) plus the distance-dependent correction from a wall sweep";
  const double after = metric("calibration", "held_out_rms_after");
  const double floor = metric("calibration", "held_out_noise_floor");
  if (std::isfinite(after)) {
    md << " (held-out error " << Mm(after) << ", noise floor of the averages " << Mm(floor) << ")";
  }
  md << ", and ΔL is noise-calibrated to metres of σ";
  const double scale = metric("calibration", "delta_l_scale");
  if (std::isfinite(scale)) md << " (σ = " << F(scale, 3) << " x ΔL in register units)";
  md << ". How the experiments are set up: docs/experiments.md.\n\n";
  std::vector<std::string> notes;
  const double n15 = metric("fig2", "rest_noise_15ms"), n4 = metric("fig2", "rest_noise_4ms");
  if (std::isfinite(n15) && std::isfinite(n4)) {
    notes.push_back(
        "**Noise against the 5 cm \"bad\" criterion.** Away from the hand, the hand scene's "
        "background (the wall at 3 m and the floor) has a temporal σ of " +
        Mm(n15) + " at 15 ms and " + Mm(n4) +
        " at 4 ms (fig. 2). A pixel with σ = 5 cm is more than 5 cm off in 32 % of its frames, "
        "so wherever σ approaches 5 cm a share of the \"bad\" pixels is noise, not a "
        "systematic error; the fig. 2 and fig. 8/9 tables separate the two.");
  }
  const double amp_off = metric("fig10-11", "off.mean_amplitude");
  const double dl_off = metric("fig10-11", "off.mean_delta_l");
  const double dl_on = metric("fig10-11", "on.mean_delta_l");
  if (std::isfinite(amp_off)) {
    notes.push_back("**Dim far walls.** The lamps' wall at 3.5 m has a mean amplitude of " +
                    F(amp_off, 3) + " register units at 15.3 ms and a mean ΔL of " + Mm(dl_off) +
                    " with the lamps off, " + Mm(dl_on) + " with them on (figs. 10/11)" +
                    (dl_off > 0.025
                         ? ": with a point emitter a wall's signal falls as 1/d², so a far "
                           "surface's σ is of the order of the 5 cm criterion at the paper's "
                           "exposures."
                         : "."));
  }
  const double sat15 = metric("fig2", "saturated_15ms"), sat4 = metric("fig2", "saturated_4ms");
  const double ia = metric("fig3", "target_intensity");
  if (std::isfinite(sat15) && std::isfinite(ia)) {
    notes.push_back("**Saturation.** The hand at 0.2 m saturates " + F(sat15, 4) +
                    " pixels per frame at 15 ms and " + F(sat4, 4) +
                    " at 4 ms (fig. 2); the pavilion's amplitude plateau starts at register " +
                    F(metric("fig3", "amplitude_max_register"), 3) + " with mean intensity " +
                    F(metric("fig3", "intensity_at_amplitude_max"), 5) + ", which puts I_A at " +
                    F(ia, 5) +
                    " (fig. 3; the paper: 15000-18000). Both are tuning targets of the "
                    "simulator, not results (see below).");
  }
  const double map_diff = metric("fig2", "bias_map_rms_difference_m");
  if (std::isfinite(map_diff)) {
    notes.push_back("**Scattering is a bias, not noise.** The hand biases " +
                    F(metric("fig2", "biased5_15ms"), 5) +
                    " background pixels by more than 5 cm at any exposure (the noise-free bias "
                    "maps at 15 and 4 ms differ by " +
                    Mm(map_diff) +
                    " RMS, fig. 2); eq. 2 sees such a bias only where it also costs amplitude "
                    "(figs. 8/9).");
  }
  const double near_i = metric("fig5", "near_intensity_at_amplitude_max");
  const double far_i = metric("fig5", "far_intensity_at_amplitude_max");
  const double pav_i = metric("fig3", "intensity_at_amplitude_max");
  if (std::isfinite(near_i) && std::isfinite(far_i) && std::isfinite(pav_i)) {
    notes.push_back(
        "**One I_A does not suit every scene.** The paper found I_A = 15000-18000 \"provided "
        "reliable results\" and sets it once. The mean intensity at the amplitude maximum, which "
        "I_A should sit a little below, is " +
        F(pav_i, 5) + " for the pavilion (fig. 3), " + F(near_i, 5) +
        " for the pavilion in fig. 5's coarser sweep and " + F(far_i, 5) +
        " for the same hall at night without near objects (fig. 5, where the amplitude still "
        "rises at the longest exposure): a fixed I_A is right for the scene it was chosen on. "
        "tofcam's default controller therefore keeps I_A fixed but schedules its gain per frame "
        "and stops at the register bound when I_A is out of reach (docs/controllers.md).");
  }
  notes.push_back(
      "**Predictions and tuning targets.** The simulator's free parameters were set once "
      "(docs/simulator.md) to reproduce three of the paper's observations, so agreeing with "
      "them is by construction and is not a result: the pavilion's amplitude plateau near "
      "I_A = 15000-18000 (fig. 3; LED power, poster distance, daylight), the hand clipping at "
      "15 ms but not at 4 ms (fig. 2; LED power, hand and wall distances), the lamps raising the "
      "intensity several-fold (figs. 10/11; lamp power and distance). Everything else below is "
      "a prediction of the physics and the paper's methods, tested against the simulator's "
      "ground truth: ΔL's noise scale (0.165 against 0.163 derived from the sensor model), "
      "the scattering bias not depending on the exposure, blooming's extra noise, what the "
      "filters remove and keep (judged by measured errors, not by the simulator's closed-form "
      "σ, which is eq. 2's own model), the calibration's held-out error, the controllers' "
      "behaviour, the finger gaps of fig. 9.");
  if (!notes.empty()) {
    md << "**Read every table with this in mind** (numbers from the runs below):\n\n";
    for (const std::string& note : notes) md << "- " << note << "\n";
    md << "\n";
  }
  return md.str();
}

}  // namespace tofcam::experiments

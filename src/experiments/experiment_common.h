#pragma once
// Helpers shared by several experiments (one file per experiment, see experiments.cc for the
// registry): formatting, the shared calibration and set point, sweeps, error pools, the
// scattering-bias measurement and the filter catalogue.

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
#include <sstream>
#include <utility>

#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/experiments/cloud_outliers.h"
#include "tofcam/experiments/experiments.h"
#include "tofcam/filters/filter_set.h"
#include "tofcam/io/importers.h"
#include "tofcam/io/png.h"
#include "tofcam/pipeline/frame_stats.h"
#include "tofcam/pipeline/metric_conversion.h"
#include "tofcam/pipeline/pipeline.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::experiments::internal {

namespace fs = std::filesystem;

using Clock = std::chrono::steady_clock;

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The "bad pixel" threshold (FrameStatsOptions::bad_error_m uses the same 5 cm).
inline constexpr double kBadErrorM = 0.05;

// The pavilion without its near bright object and without daylight: the poster hangs on the
// back wall (5.4 m) and it is night. Nothing in it saturates up to register 255.
inline constexpr const char* kCalmHall = "pavilion?poster_distance_m=5.4&daylight_w_m2=0";

// Intensity from which a pixel counts as clipped (the controller's and the sweep's rule).
inline const double kClippedIntensity = ControllerOptions{}.clipped_intensity;

std::string F(double value, int digits = 4);

std::string I(long long value);

std::string Pct(double fraction);

std::string Mm(double value_m);

int Scaled(int full, double effort, int minimum);

// ---- shared setup: the paper's calibration (eq. 1) and the noise calibration of ΔL ----------

struct Shared {
  sim::CameraModel model;
  CameraInfo info;
  OffsetCalibration offsets;      // paper eq. 1 only (white wall at 2 m)
  OffsetCalibration calibration;  // eq. 1 refined + distance correction: what frames get
  double delta_l_scale = 1.0;
  WallCalibrationReport report;
  SweepOptions sweep;
  SweepReport sweep_report;
};

sim::SimulatorOptions Sim(const ExperimentOptions& o, std::uint64_t offset, int reg);

// Calibrating costs ~2 s; experiments run in one process share it (keyed by seed).
const Shared& GetShared(const ExperimentOptions& o);
// The same calibration of the simulated SR-2 run at another modulation frequency (the camera
// model's only one), for dual-frequency pipelines; keyed by seed and frequency.
const Shared& GetSharedAt(const ExperimentOptions& o, double modulation_frequency_hz);

// Pipeline without controller and cloud, calibrated, ΔL in metres of σ (noise-calibrated).
PipelineOptions BaseOptions(const Shared& s);

PipelineOptions RawOptions(const Shared& s);

// Grabs frames until the camera's exposure start reaches `time_s` (scene time).
Frame GrabAt(sim::SimulatedCamera& camera, double time_s);

// Error of pixel i against the truth; NaN without a finite truth.
double ErrorAt(const MetricFrame& f, std::size_t i);

bool IsBad(const MetricFrame& f, std::size_t i);

// Pooled error statistics of a set of pixels.
struct ErrorPool {
  long long pixels = 0;
  long long finite = 0;
  long long bad = 0;
  double sum_sq = 0.0;
  double sum_delta_l = 0.0;
  long long delta_l_n = 0;
  void Add(const MetricFrame& f, std::size_t i) {
    ++pixels;
    const double e = ErrorAt(f, i);
    if (std::isfinite(e)) {
      ++finite;
      sum_sq += e * e;
    }
    if (IsBad(f, i)) ++bad;
    if (!f.delta_l_m.empty() && std::isfinite(f.delta_l_m[i])) {
      sum_delta_l += f.delta_l_m[i];
      ++delta_l_n;
    }
  }
  [[nodiscard]] double Rmse() const { return finite ? std::sqrt(sum_sq / finite) : kNaN; }
  [[nodiscard]] double BadFraction() const {
    return pixels ? static_cast<double>(bad) / pixels : kNaN;
  }
  [[nodiscard]] double MeanDeltaL() const { return delta_l_n ? sum_delta_l / delta_l_n : kNaN; }
};

Table MatrixTable(const std::string& file, const Image<float>& m);

double Ratio(long long a, long long b);

// ---- register sweeps (fig. 3, fig. 5) --------------------------------------------------------

struct SweepRow {
  int reg = 0;
  double time_ms = 0.0;
  double mean_distance_m = 0.0;
  double mean_amplitude = 0.0;
  double mean_intensity = 0.0;
  double saturated_fraction = 0.0;
  double rmse_m = 0.0;
};

std::vector<SweepRow> RegisterSweep(const std::string& spec, const std::vector<int>& registers,
                                    const ExperimentOptions& o, std::uint64_t seed_offset);

std::vector<int> RegisterGrid(int step);

// Least-squares line y = a + b x over rows [0, end).
std::pair<double, double> FitLine(const std::vector<double>& x, const std::vector<double>& y);

// Amplitude maximum, saturation onset (first register with >= 0.5 % truly saturated pixels:
// a handful of glints is not "saturation" of the scene) and linear fits over the registers
// before the onset.
struct SweepSummary {
  int amplitude_max_register = 0;
  double amplitude_max = 0.0;
  double intensity_at_amplitude_max = 0.0;
  int saturation_onset_register = 0;
  double intensity_at_onset = 0.0;
  std::pair<double, double> amplitude_fit, intensity_fit;  // a + b * register
};

SweepSummary Summarise(const std::vector<SweepRow>& rows);

// The paper's working point from a sweep, by the library's own rule (ChooseSetpoint): the start
// of the amplitude plateau, I_A a little below the intensity there, c_0 and V_p.
ControllerSetpoint SetpointOf(const std::vector<SweepRow>& rows);

// ---- fig. 2, fig. 8/9: the hand ---------------------------------------------------------------

// A pixel is background behind a hand held 0.2-0.25 m from the lens when its true distance exceeds
// this: the nearest other surfaces of the `hand` and `demo` scenes are 0.9 m away.
inline constexpr double kBackgroundM = 0.5;

inline constexpr double kRegisterMs = 0.255;  // SR-2: 255 µs per register step

inline constexpr float kNaNf = std::numeric_limits<float>::quiet_NaN();

// The scattering bias of one view: noise-free twin renderings (no shot or read noise) with the
// in-camera scattering PSF on and off. Everything else (fixed pattern, wiggling, saturation,
// blooming) is the same in both and cancels in the difference; bloomed charge lands in the four
// taps alike, so it cannot shift a phase either.
struct ScatteringBias {
  Image<float> bias_m;           // with scattering - without, wrapped to [-L/2, L/2); NaN: no phase
  Image<float> amplitude_ratio;  // amplitude with scattering / without
};

ScatteringBias MeasureScatteringBias(const sim::Scene& scene, int reg, double time_s,
                                     const ExperimentOptions& o);

// ---- mirror ---------------------------------------------------------------------------------

struct NamedFilter {
  std::string name;
  std::string parameter;
  FilterSetOptions options;
};

FilterSetOptions NoFilters();

std::vector<NamedFilter> FilterCatalogue(bool sweeps);

// The experiments, one file each; experiments.cc maps their names to them.
ExperimentResult Fig2(const ExperimentOptions& o);
ExperimentResult Fig3(const ExperimentOptions& o);
ExperimentResult Fig5(const ExperimentOptions& o);
ExperimentResult Fig67(const ExperimentOptions& o);
ExperimentResult Fig89(const ExperimentOptions& o);
ExperimentResult Fig1011(const ExperimentOptions& o);
ExperimentResult Mirror(const ExperimentOptions& o);
ExperimentResult Calibration(const ExperimentOptions& o);
ExperimentResult Controllers(const ExperimentOptions& o);
ExperimentResult Filters(const ExperimentOptions& o);
ExperimentResult RealData(const ExperimentOptions& o);
ExperimentResult Beyond(const ExperimentOptions& o);

}  // namespace tofcam::experiments::internal

#include "experiment_common.h"

namespace tofcam::experiments::internal {

std::string F(double value, int digits) {
  if (!std::isfinite(value)) return "nan";
  char buffer[48];
  std::snprintf(buffer, sizeof buffer, "%.*g", digits, value);
  return buffer;
}

std::string I(long long value) { return std::to_string(value); }

std::string Pct(double fraction) {
  if (!std::isfinite(fraction)) return "-";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1f %%", 100.0 * fraction);
  return buffer;
}

std::string Mm(double value_m) {
  if (!std::isfinite(value_m)) return "-";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1f mm", value_m * 1e3);
  return buffer;
}

int Scaled(int full, double effort, int minimum) {
  return std::max(minimum, static_cast<int>(std::lround(full * effort)));
}

sim::SimulatorOptions Sim(const ExperimentOptions& o, std::uint64_t offset, int reg) {
  sim::SimulatorOptions s;
  s.seed = o.seed + offset;
  s.threads = o.threads;
  s.integration_time_register = reg;
  return s;
}

namespace {

// Eq. 1 at a white wall at 2 m, then the wall sweep of issue 4 on top: without it every distance
// but the calibration wall's keeps its wiggling residual (~3 cm, see the calibration experiment),
// which would count as "bad" in every error statistic and hide the noise and artefacts the
// figures are about. `model` runs at its first frequency.
void CalibrateSimulated(const sim::CameraModel& model, const ExperimentOptions& o,
                        std::uint64_t seed_offset, Shared& out) {
  sim::SimulatedCamera wall(sim::LoadBuiltinScene("wall", {{"distance_m", "2.0"}}), model,
                            Sim(o, 1000 + seed_offset, 0));
  WallCalibrationOptions wall_options;
  wall_options.wall_distance_m = 2.0;
  out.offsets = CalibrateOffsets(wall, wall_options, {}, &out.report);
  std::unique_ptr<sim::SimulatedCamera> sweep_camera;
  int calls = 0;
  const WallCameraSource source = [&](double d) -> Camera& {
    sweep_camera = std::make_unique<sim::SimulatedCamera>(
        sim::LoadBuiltinScene("wall", {{"distance_m", F(d, 6)}}), model,
        Sim(o, 100 + seed_offset + calls++, 0));
    return *sweep_camera;
  };
  out.sweep.step_m = o.effort >= 1.0 ? 0.25 : 0.5;
  out.sweep.frames_per_distance = Scaled(10, o.effort, 3);
  out.calibration =
      CalibrateDistanceCorrection(out.offsets, source, out.sweep, {}, &out.sweep_report);
  std::vector<MetricFrame> frames;
  for (int k = 0; k < 20; ++k) frames.push_back(ConvertToMetric(*wall.Grab()));
  out.delta_l_scale = FitDeltaLScale(frames).scale;
}

}  // namespace

const Shared& GetShared(const ExperimentOptions& o) {
  static std::mutex mutex;
  static std::map<std::uint64_t, std::unique_ptr<Shared>> cache;
  std::lock_guard<std::mutex> lock(mutex);
  auto it = cache.find(o.seed);
  if (it != cache.end()) return *it->second;
  auto shared = std::make_unique<Shared>();
  shared->model = sim::ResolveCameraModel("sr2");
  shared->info = shared->model.Info(shared->model.modulation_frequencies_hz.front());
  CalibrateSimulated(shared->model, o, 0, *shared);
  return *cache.emplace(o.seed, std::move(shared)).first->second;
}

const Shared& GetSharedAt(const ExperimentOptions& o, double modulation_frequency_hz) {
  static std::mutex mutex;
  static std::map<std::pair<std::uint64_t, double>, std::unique_ptr<Shared>> cache;
  std::lock_guard<std::mutex> lock(mutex);
  const auto key = std::make_pair(o.seed, modulation_frequency_hz);
  auto it = cache.find(key);
  if (it != cache.end()) return *it->second;
  auto shared = std::make_unique<Shared>();
  shared->model = sim::ResolveCameraModel("sr2");
  shared->model.modulation_frequencies_hz = {modulation_frequency_hz};
  shared->info = shared->model.Info(modulation_frequency_hz);
  CalibrateSimulated(shared->model, o, 5000, *shared);
  return *cache.emplace(key, std::move(shared)).first->second;
}

PipelineOptions BaseOptions(const Shared& s) {
  PipelineOptions p;
  p.calibration = s.calibration;
  p.accuracy.scale = s.delta_l_scale;
  p.controller_enabled = false;
  p.cloud_enabled = false;
  return p;
}

PipelineOptions RawOptions(const Shared& s) {
  PipelineOptions p = BaseOptions(s);
  p.filters.accuracy_enabled = false;
  p.filters.saturation_enabled = false;
  return p;
}

Frame GrabAt(sim::SimulatedCamera& camera, double time_s) {
  while (camera.NextExposureStartS() + 1e-9 < time_s) (void)camera.Grab();
  return *camera.Grab();
}

double ErrorAt(const MetricFrame& f, std::size_t i) {
  const double truth = f.truth->radial_distance_m[i];
  if (!std::isfinite(truth)) return kNaN;
  return static_cast<double>(f.radial_distance_m[i]) - truth;
}

bool IsBad(const MetricFrame& f, std::size_t i) {
  const double e = ErrorAt(f, i);
  return !std::isfinite(e) || std::abs(e) > kBadErrorM;
}

Table MatrixTable(const std::string& file, const Image<float>& m) {
  Table t{file, {}, {}, false};
  for (int c = 0; c < m.width(); ++c) t.columns.push_back("c" + std::to_string(c));
  for (int row = 0; row < m.height(); ++row) {
    std::vector<std::string> cells;
    for (int c = 0; c < m.width(); ++c) cells.push_back(F(m(row, c), 4));
    t.rows.push_back(std::move(cells));
  }
  return t;
}

double Ratio(long long a, long long b) { return b ? static_cast<double>(a) / b : kNaN; }

std::vector<SweepRow> RegisterSweep(const std::string& spec, const std::vector<int>& registers,
                                    const ExperimentOptions& o, std::uint64_t seed_offset) {
  const Shared& s = GetShared(o);
  auto [name, overrides] = sim::ParseSceneSpec(spec);
  sim::SimulatedCamera camera(sim::LoadBuiltinScene(name, overrides), s.model,
                              Sim(o, seed_offset, registers.front()));
  Pipeline pipeline(RawOptions(s), camera.Info());
  std::vector<SweepRow> rows;
  PipelineResult result;
  for (int reg : registers) {
    camera.SetIntegrationTimeRegister(reg);
    pipeline.Process(*camera.Grab(), result);
    const MetricFrame& f = result.frame;
    SweepRow row;
    row.reg = reg;
    row.time_ms = f.info.integration_time_us * 1e-3;
    double sd = 0, sa = 0, si = 0;
    long long n = 0, n_distance = 0, saturated = 0;
    ErrorPool pool;
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      if (f.truth->causes[i].Has(Flag::kSaturated)) ++saturated;
      // The same pixels as SweepIntegrationTime: every reading, including pixels whose taps all
      // clipped (amplitude 0, no phase, full-scale intensity); the distance statistics only
      // over pixels with a phase.
      const bool valid = f.flags[i].Valid();
      if (!CountsForExposure(f, i, kRejectMask, kClippedIntensity)) continue;
      ++n;
      sa += f.amplitude[i];
      si += f.intensity[i];
      if (!valid) continue;
      ++n_distance;
      sd += f.radial_distance_m[i];
      pool.Add(f, i);
    }
    row.mean_distance_m = n_distance ? sd / n_distance : kNaN;
    row.mean_amplitude = n ? sa / n : kNaN;
    row.mean_intensity = n ? si / n : kNaN;
    row.saturated_fraction = static_cast<double>(saturated) / f.radial_distance_m.size();
    row.rmse_m = pool.Rmse();
    rows.push_back(row);
  }
  return rows;
}

std::vector<int> RegisterGrid(int step) {
  std::vector<int> regs;
  for (int r = 1; r <= 255; r += step) regs.push_back(r);
  if (regs.back() != 255) regs.push_back(255);
  return regs;
}

std::pair<double, double> FitLine(const std::vector<double>& x, const std::vector<double>& y) {
  const double n = static_cast<double>(x.size());
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    sx += x[i];
    sy += y[i];
    sxx += x[i] * x[i];
    sxy += x[i] * y[i];
  }
  const double den = n * sxx - sx * sx;
  if (n < 2 || den == 0) return {kNaN, kNaN};
  const double b = (n * sxy - sx * sy) / den;
  return {(sy - b * sx) / n, b};
}

SweepSummary Summarise(const std::vector<SweepRow>& rows) {
  SweepSummary s;
  for (const SweepRow& r : rows) {
    if (r.mean_amplitude > s.amplitude_max) {
      s.amplitude_max = r.mean_amplitude;
      s.amplitude_max_register = r.reg;
      s.intensity_at_amplitude_max = r.mean_intensity;
    }
  }
  s.saturation_onset_register = rows.back().reg;
  s.intensity_at_onset = rows.back().mean_intensity;
  for (const SweepRow& r : rows) {
    if (r.saturated_fraction >= 0.005) {
      s.saturation_onset_register = r.reg;
      s.intensity_at_onset = r.mean_intensity;
      break;
    }
  }
  std::vector<double> x, ya, yi;
  for (const SweepRow& r : rows) {
    if (r.reg >= s.saturation_onset_register) break;
    x.push_back(r.reg);
    ya.push_back(r.mean_amplitude);
    yi.push_back(r.mean_intensity);
  }
  s.amplitude_fit = FitLine(x, ya);
  s.intensity_fit = FitLine(x, yi);
  return s;
}

ControllerSetpoint SetpointOf(const std::vector<SweepRow>& rows) {
  std::vector<IntegrationSweepPoint> points;
  for (const SweepRow& r : rows) {
    points.push_back({r.reg, r.mean_intensity, r.mean_amplitude, r.saturated_fraction});
  }
  return ChooseSetpoint(points);
}

ScatteringBias MeasureScatteringBias(const sim::Scene& scene, int reg, double time_s,
                                     const ExperimentOptions& o) {
  const Shared& s = GetShared(o);
  const auto render = [&](bool scattering) {
    sim::SimulatorOptions so = Sim(o, 900, reg);
    so.shot_noise = false;
    so.read_noise = false;
    so.scattering = scattering;
    sim::SimulatedCamera camera(scene, s.model, so);
    return ConvertToMetric(GrabAt(camera, time_s));
  };
  const MetricFrame on = render(true), off = render(false);
  const double range = s.info.unambiguous_range_m();
  ScatteringBias b{Image<float>(on.width(), on.height(), kNaNf),
                   Image<float>(on.width(), on.height(), kNaNf)};
  for (std::size_t i = 0; i < b.bias_m.size(); ++i) {
    if (!on.flags[i].Valid() || !off.flags[i].Valid()) continue;
    double d = static_cast<double>(on.radial_distance_m[i]) - off.radial_distance_m[i];
    d -= range * std::floor(d / range + 0.5);
    b.bias_m[i] = static_cast<float>(d);
    if (off.amplitude[i] > 0) b.amplitude_ratio[i] = on.amplitude[i] / off.amplitude[i];
  }
  return b;
}

FilterSetOptions NoFilters() {
  FilterSetOptions f;
  f.saturation_enabled = false;
  f.accuracy_enabled = false;
  return f;
}

std::vector<NamedFilter> FilterCatalogue(bool sweeps) {
  std::vector<NamedFilter> list;
  const std::vector<double> accuracy =
      sweeps ? std::vector<double>{0.01, 0.02, 0.03, 0.05, 0.07, 0.1, 0.15, 0.25}
             : std::vector<double>{0.07};
  for (double t : accuracy) {
    NamedFilter f{"accuracy", F(t, 3), NoFilters()};
    f.options.accuracy_enabled = true;
    f.options.accuracy.max_delta_l_m = t;
    list.push_back(f);
  }
  const std::vector<double> amplitude =
      sweeps ? std::vector<double>{25, 50, 100, 200, 400, 800} : std::vector<double>{100};
  for (double a : amplitude) {
    NamedFilter f{"amplitude", F(a, 4), NoFilters()};
    f.options.amplitude_enabled = true;
    f.options.amplitude.min_amplitude = a;
    list.push_back(f);
  }
  {
    NamedFilter f{"saturation", "default", NoFilters()};
    f.options.saturation_enabled = true;
    list.push_back(f);
  }
  const std::vector<double> angles =
      sweeps ? std::vector<double>{140, 150, 160, 170} : std::vector<double>{160};
  for (double a : angles) {
    NamedFilter f{"jump-edge", F(a, 4), NoFilters()};
    f.options.jump_edge_enabled = true;
    f.options.jump_edge.max_angle_deg = a;
    list.push_back(f);
  }
  {
    NamedFilter f{"edge-aware", "libfreenect2", NoFilters()};
    f.options.flying_pixel_enabled = true;
    list.push_back(f);
  }
  const std::vector<int> cells = sweeps ? std::vector<int>{2, 4, 8, 16} : std::vector<int>{4};
  for (int m : cells) {
    NamedFilter f{"weingarten", I(m), NoFilters()};
    f.options.weingarten_enabled = true;
    f.options.weingarten.min_points = m;
    list.push_back(f);
  }
  if (sweeps) {
    for (double t : {0.03, 0.05, 0.07}) {
      NamedFilter f{"combination", "sat+acc " + F(t, 3) + "+jump 160", NoFilters()};
      f.options.saturation_enabled = true;
      f.options.accuracy_enabled = true;
      f.options.accuracy.max_delta_l_m = t;
      f.options.jump_edge_enabled = true;
      list.push_back(f);
      NamedFilter g = f;
      g.parameter = "sat+acc " + F(t, 3) + "+jump 160+edge-aware";
      g.options.flying_pixel_enabled = true;
      list.push_back(g);
    }
  }
  return list;
}

}  // namespace tofcam::experiments::internal

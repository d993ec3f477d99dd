// `tofcam noise-check`: how well each noise predictor of a camera (eq. 2, the fitted model, the
// camera's own confidence) ranks and predicts the temporal σ of a static recording, on held-out
// pixels; prints a table and draws predicted against measured σ per decile (docs/noise_model.md).
#include <cairo.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "camera_source.h"
#include "commands.h"
#include "tofcam/accuracy/noise_model.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam::cli {
namespace {

struct NoiseCheckOptions {
  std::string camera;
  int frames = 30;
  std::string png;
  bool no_confidence = false;
  CameraSourceOptions source;
};

// A cairo surface's PNG bytes, for the atomic write.
cairo_status_t AppendBytes(void* closure, const unsigned char* data, unsigned int length) {
  static_cast<std::string*>(closure)->append(reinterpret_cast<const char*>(data), length);
  return CAIRO_STATUS_SUCCESS;
}

// Predicted against measured σ per decile on log-log axes, with the ±25 % band of the target.
void DrawChart(const NoiseModelFit& fit, const std::string& title,
               const std::filesystem::path& path) {
  constexpr int kW = 720, kH = 540;
  constexpr double kLeft = 80, kRight = 20, kTop = 50, kBottom = 60;
  double lo = 1e9, hi = 0.0;
  for (const PredictorValidation* v : {&fit.eq2, &fit.fitted}) {
    for (int d = 0; d < 10; ++d) {
      for (double x : {v->predicted_m[d], v->measured_m[d]}) {
        if (x > 0.0 && std::isfinite(x)) {
          lo = std::min(lo, x);
          hi = std::max(hi, x);
        }
      }
    }
  }
  if (!(hi > lo)) {
    lo = 1e-4;
    hi = 1e-1;
  }
  const double llo = std::floor(std::log10(lo * 0.8) * 4) / 4;
  const double lhi = std::ceil(std::log10(hi * 1.25) * 4) / 4;
  const double pw = kW - kLeft - kRight, ph = kH - kTop - kBottom;
  auto px = [&](double v) { return kLeft + (std::log10(v) - llo) / (lhi - llo) * pw; };
  auto py = [&](double v) { return kTop + ph - (std::log10(v) - llo) / (lhi - llo) * ph; };

  std::unique_ptr<cairo_surface_t, decltype(&cairo_surface_destroy)> surface(
      cairo_image_surface_create(CAIRO_FORMAT_RGB24, kW, kH), cairo_surface_destroy);
  std::unique_ptr<cairo_t, decltype(&cairo_destroy)> cr_owner(cairo_create(surface.get()),
                                                              cairo_destroy);
  cairo_t* cr = cr_owner.get();
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_paint(cr);
  cairo_select_font_face(cr, "sans-serif", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  // The ±25 % band around predicted = measured.
  cairo_set_source_rgb(cr, 0.9, 0.9, 0.9);
  const double a = std::pow(10.0, llo), b = std::pow(10.0, lhi);
  cairo_save(cr);
  cairo_rectangle(cr, kLeft, kTop, pw, ph);
  cairo_clip(cr);
  cairo_move_to(cr, px(a), py(a * 1.25));
  cairo_line_to(cr, px(b), py(b * 1.25));
  cairo_line_to(cr, px(b), py(b / 1.25));
  cairo_line_to(cr, px(a), py(a / 1.25));
  cairo_close_path(cr);
  cairo_fill(cr);
  cairo_restore(cr);
  // Grid and labels at 1-2-5 steps in millimetres.
  cairo_set_font_size(cr, 12);
  cairo_set_line_width(cr, 1);
  for (int e = static_cast<int>(std::floor(llo)); e <= static_cast<int>(std::ceil(lhi)); ++e) {
    for (double m : {1.0, 2.0, 5.0}) {
      const double v = m * std::pow(10.0, e);
      if (std::log10(v) < llo - 1e-9 || std::log10(v) > lhi + 1e-9) continue;
      cairo_set_source_rgb(cr, 0.8, 0.8, 0.8);
      cairo_move_to(cr, px(v), kTop);
      cairo_line_to(cr, px(v), kTop + ph);
      cairo_move_to(cr, kLeft, py(v));
      cairo_line_to(cr, kLeft + pw, py(v));
      cairo_stroke(cr);
      char label[32];
      std::snprintf(label, sizeof label, "%g", v * 1e3);
      cairo_set_source_rgb(cr, 0, 0, 0);
      cairo_move_to(cr, px(v) - 8, kTop + ph + 16);
      cairo_show_text(cr, label);
      cairo_move_to(cr, kLeft - 40, py(v) + 4);
      cairo_show_text(cr, label);
    }
  }
  cairo_set_source_rgb(cr, 0, 0, 0);
  cairo_rectangle(cr, kLeft, kTop, pw, ph);
  cairo_stroke(cr);
  cairo_move_to(cr, px(a), py(a));
  cairo_line_to(cr, px(b), py(b));
  cairo_stroke(cr);
  cairo_move_to(cr, kLeft + pw / 2 - 120, kH - 15);
  cairo_show_text(cr, "predicted sigma per decile (mm, log)");
  cairo_save(cr);
  cairo_move_to(cr, 20, kTop + ph / 2 + 90);
  cairo_rotate(cr, -kPi / 2);
  cairo_show_text(cr, "measured temporal sigma (mm, log)");
  cairo_restore(cr);
  cairo_set_font_size(cr, 14);
  cairo_move_to(cr, kLeft, 30);
  cairo_show_text(cr, title.c_str());
  // The predictors, with their held-out rank correlation in the legend.
  struct Series {
    const PredictorValidation* v;
    double r, g, b;
  };
  const Series series[] = {{&fit.eq2, 0.12, 0.47, 0.71}, {&fit.fitted, 1.0, 0.5, 0.05}};
  cairo_set_font_size(cr, 12);
  double legend_y = kTop + 20;
  for (const Series& s : series) {
    cairo_set_source_rgb(cr, s.r, s.g, s.b);
    cairo_set_line_width(cr, 2);
    for (int d = 0; d < 10; ++d) {
      const double x = px(s.v->predicted_m[d]), y = py(s.v->measured_m[d]);
      if (d == 0) {
        cairo_move_to(cr, x, y);
      } else {
        cairo_line_to(cr, x, y);
      }
    }
    cairo_stroke(cr);
    for (int d = 0; d < 10; ++d) {
      cairo_arc(cr, px(s.v->predicted_m[d]), py(s.v->measured_m[d]), 4, 0, 2 * kPi);
      cairo_fill(cr);
    }
    char text[160];
    std::snprintf(text, sizeof text, "%s: rho %.3f, worst decile %.0f %%", s.v->name.c_str(),
                  s.v->spearman, 100 * s.v->max_decile_error);
    cairo_rectangle(cr, kLeft + 12, legend_y - 9, 10, 10);
    cairo_fill(cr);
    cairo_set_source_rgb(cr, 0, 0, 0);
    cairo_move_to(cr, kLeft + 28, legend_y);
    cairo_show_text(cr, text);
    legend_y += 18;
  }
  if (fit.vendor.available) {
    char text[120];
    std::snprintf(text, sizeof text, "vendor confidence: rho %.3f (ranks only)",
                  fit.vendor.spearman);
    cairo_move_to(cr, kLeft + 28, legend_y);
    cairo_show_text(cr, text);
    legend_y += 18;
  }
  cairo_move_to(cr, kLeft + 28, legend_y);
  cairo_show_text(cr, "grey: within 25 % of predicted");
  cairo_surface_flush(surface.get());
  std::string bytes;
  if (cairo_surface_write_to_png_stream(surface.get(), AppendBytes, &bytes) !=
      CAIRO_STATUS_SUCCESS) {
    throw Error(ErrorCode::kIo, path.string() + ": cannot encode the chart as PNG");
  }
  WriteFileAtomically(path, bytes);
}

void PrintValidation(const PredictorValidation& v, const std::string& label) {
  if (!v.available) {
    std::printf("  %-24s  not available (the source has no such channel)\n", label.c_str());
    return;
  }
  if (!v.calibrated) {
    std::printf("  %-24s  %6.3f   ranks only (unitless)\n", label.c_str(), v.spearman);
    return;
  }
  std::printf("  %-24s  %6.3f   %5.0f %%\n", label.c_str(), v.spearman, 100 * v.max_decile_error);
}

void RunNoiseCheck(const NoiseCheckOptions& o) {
  if (o.frames < 3 || o.frames > 100000) {
    throw Error(ErrorCode::kInvalidArgument,
                "--frames " + std::to_string(o.frames) + " must be in [3, 100000]");
  }
  std::unique_ptr<Camera> camera = OpenCamera(o.camera, o.source);
  std::vector<MetricFrame> frames;
  for (int n = 1; n <= o.frames; ++n) {
    std::optional<Frame> frame = camera->Grab();
    if (!frame) break;  // a finite source: use what it had
    frames.push_back(ConvertToMetric(*frame));
    if (n % 10 == 0) std::fprintf(stderr, "noise-check: grabbed %d/%d frames\n", n, o.frames);
  }
  NoiseModelFitOptions options;
  options.use_confidence = !o.no_confidence;
  // Three frames are accepted (some real sample files have no more), with a warning.
  options.min_frames = 3;
  if (frames.size() < static_cast<std::size_t>(options.min_frames)) {
    throw Error(ErrorCode::kIo, o.camera + " delivered " + std::to_string(frames.size()) +
                                    " frames; noise-check needs at least " +
                                    std::to_string(options.min_frames) + " static frames");
  }
  if (frames.size() < 4) {
    std::fprintf(stderr,
                 "noise-check: warning: %zu frames; a per-pixel sigma from so few frames scatters "
                 "by about 50 %%, so the ranks below are noisy\n",
                 frames.size());
  }
  const NoiseModelFit fit = FitNoiseModel(frames, options);
  const CameraInfo& info = camera->Info();
  std::printf("noise-check: %zu static frames of %s (%d x %d), %d training / %d held-out pixels\n",
              frames.size(), info.model.c_str(), info.width(), info.height(), fit.training_pixels,
              fit.held_out_pixels);
  std::printf("  %-24s  %6s   %s\n", "predictor (held out)", "rho", "worst decile |pred/meas-1|");
  char eq2[64];
  std::snprintf(eq2, sizeof eq2, "eq. 2 (scale %.3g)", fit.eq2_scale);
  PrintValidation(fit.eq2, eq2);
  PrintValidation(fit.fitted, "fitted model");
  PrintValidation(fit.vendor, "vendor confidence");
  const NoiseModel& m = fit.model;
  std::printf(
      "fitted model (%s): ln sigma = %.4g %+.4g ln A %+.4g ln I %+.4g ln r %+.4g A/%.5g %+.4g "
      "ln(1+C) %+.4g ln(1+E/%.3g m)\n",
      fit.features.c_str(), m.intercept, m.log_amplitude, m.log_intensity, m.log_distance,
      m.amplitude_fraction, m.amplitude_ref, m.log_confidence, m.log_edge, m.edge_ref_m);
  std::printf("  decile  eq2_pred_mm  model_pred_mm  measured_mm\n");
  for (int d = 0; d < 10; ++d) {
    // The two predictors sort the pixels differently: each decile's measured σ is the model's.
    std::printf("  %6d  %11.3f  %13.3f  %11.3f\n", d + 1, fit.eq2.predicted_m[d] * 1e3,
                fit.fitted.predicted_m[d] * 1e3, fit.fitted.measured_m[d] * 1e3);
  }
  // A tie is a tie: Spearman's ρ over n pixels has a standard error of about
  // (1 - ρ²) sqrt((1 + ρ²/2) / (n - 3)) (Bonett & Wright 2000, through Fisher's z).
  const bool vendor_best = fit.vendor.available && fit.vendor.spearman > fit.eq2.spearman;
  const PredictorValidation& other = vendor_best ? fit.vendor : fit.eq2;
  const double rho = other.spearman, n = fit.held_out_pixels;
  const double se = (1 - rho * rho) * std::sqrt((1 + rho * rho / 2) / std::max(n - 3, 1.0));
  const double diff = fit.fitted.spearman - rho;
  const char* rank = diff > 2 * se     ? "ranks better than"
                     : diff >= -2 * se ? "ranks as well as (within 2 standard errors)"
                                       : "ranks WORSE than";
  std::printf("verdict: the fitted model %s %s (rho %.3f vs %.3f, standard error %.3f) and %s\n",
              rank, other.name.c_str(), fit.fitted.spearman, rho, se,
              fit.fitted.max_decile_error <= 0.25 ? "predicts every decile within 25 %"
                                                  : "misses the 25 % decile target");
  if (!o.png.empty()) {
    DrawChart(fit, "noise-check: " + info.model + ", " + std::to_string(frames.size()) + " frames",
              o.png);
    std::printf("chart: %s\n", o.png.c_str());
  }
}

void SetupNoiseCheckCommand(CLI::App& app) {
  auto o = std::make_shared<NoiseCheckOptions>();
  CLI::App* sub = app.add_subcommand(
      "noise-check",
      "How well eq. 2, a fitted noise model and the camera's own confidence predict the temporal "
      "noise of a static recording (held-out pixels)");
  sub->add_option("--camera", o->camera, "Static source: " + CameraSourceHelp())->required();
  sub->add_option("--frames", o->frames, "Static frames to use (3..100000)")->capture_default_str();
  sub->add_option("--png", o->png, "Write predicted vs measured sigma per decile to this PNG");
  sub->add_flag("--no-confidence", o->no_confidence,
                "Leave the camera's confidence channel out of the fitted model");
  sub->add_option("--integration-register", o->source.integration_time_register,
                  "Integration-time register to open the camera with (0 = its default)")
      ->capture_default_str();
  sub->add_option("--seed", o->source.seed, "Simulator noise seed")
      ->check(kNonNegative)
      ->capture_default_str();
  AddRos2DomainOption(sub, o->source.ros2_domain);
  sub->add_option("--camera-model", o->source.camera_model, "Simulator camera model");
  sub->callback([o] { RunNoiseCheck(*o); });
}

TOFCAM_REGISTER_COMMAND("noise-check", SetupNoiseCheckCommand);

}  // namespace
}  // namespace tofcam::cli

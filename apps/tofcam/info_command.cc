// `tofcam info`: prints the camera model's geometry and register conventions.
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "commands.h"
#include "tofcam/tofcam.h"

namespace tofcam::cli {
namespace {

struct InfoOptions {
  std::string model = "sr2";
  double modulation_frequency_hz = 20e6;
};

void RunInfo(const InfoOptions& o) {
  if (o.model != "sr2") {
    throw Error(ErrorCode::kNotFound, "unknown camera model '" + o.model + "' (known: sr2)");
  }
  if (!(o.modulation_frequency_hz > 0) || !std::isfinite(o.modulation_frequency_hz)) {
    throw Error(ErrorCode::kInvalidArgument, "--modulation-frequency-hz must be > 0");
  }
  const CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  const double deg = 180.0 / kPi;
  const double range = UnambiguousRangeM(o.modulation_frequency_hz);
  std::printf("tofcam %s\n", kVersionString);
  std::printf("model               SR-2 (CSEM SwissRanger)\n");
  std::printf("resolution          %d x %d px\n", k.width, k.height);
  std::printf("focal length        fx %.3f px, fy %.3f px\n", k.fx_px, k.fy_px);
  std::printf("principal point     (%.2f, %.2f) px\n", k.cx_px, k.cy_px);
  std::printf("field of view       %.2f deg x %.2f deg\n", k.HorizontalFovRad() * deg,
              k.VerticalFovRad() * deg);
  std::printf("modulation          %.3f MHz\n", o.modulation_frequency_hz * 1e-6);
  std::printf("unambiguous range   %.4f m (%.4f mm per distance step)\n", range,
              range / kDistanceRegisterSpan * 1e3);
  std::printf("integration time    register 1..255 x 255 us (0.255 .. 65.025 ms)\n");
}

void SetupInfoCommand(CLI::App& app) {
  auto opts = std::make_shared<InfoOptions>();
  CLI::App* sub = app.add_subcommand("info", "Print camera geometry and register conventions");
  sub->add_option("--model", opts->model, "Camera model")->capture_default_str();
  sub->add_option("--modulation-frequency-hz", opts->modulation_frequency_hz,
                  "Modulation frequency in Hz")
      ->capture_default_str();
  sub->callback([opts] { RunInfo(*opts); });
}

TOFCAM_REGISTER_COMMAND("info", SetupInfoCommand);

}  // namespace

}  // namespace tofcam::cli

#include "tofcam/sim/camera_model.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "tofcam/core/error.h"

namespace tofcam::sim {
namespace {

TEST(CameraModelTest, BuiltinModelsLoadAndValidate) {
  const auto names = BuiltinCameraModelNames();
  ASSERT_EQ(names.size(), 4u);
  for (const auto& n : names) {
    const CameraModel m = ResolveCameraModel(n);
    EXPECT_NO_THROW(m.Validate()) << n;
  }
  // The default SR-2 must match the foundation's intrinsics (tof-notes section 3).
  const CameraModel sr2 = ResolveCameraModel("");
  EXPECT_EQ(sr2.name, "SR-2");
  EXPECT_EQ(sr2.intrinsics.width, 160);
  EXPECT_EQ(sr2.intrinsics.height, 124);
  // Exactly equal, so calibration files made with CameraIntrinsics::SwissRangerSr2() match.
  EXPECT_DOUBLE_EQ(sr2.intrinsics.fx_px, CameraIntrinsics::SwissRangerSr2().fx_px);
  EXPECT_DOUBLE_EQ(sr2.intrinsics.fy_px, CameraIntrinsics::SwissRangerSr2().fy_px);
  EXPECT_DOUBLE_EQ(sr2.intrinsics.cx_px, CameraIntrinsics::SwissRangerSr2().cx_px);
  EXPECT_DOUBLE_EQ(sr2.intrinsics.cy_px, CameraIntrinsics::SwissRangerSr2().cy_px);
  EXPECT_DOUBLE_EQ(sr2.integration_time_step_us, 255.0);
  EXPECT_EQ(sr2.min_integration_register, 1);
  EXPECT_EQ(sr2.max_integration_register, 255);
  EXPECT_DOUBLE_EQ(sr2.Info(20e6).IntegrationTimeUs(255), 65025.0);
  const CameraModel big = ResolveCameraModel("generic640x480");
  EXPECT_EQ(big.intrinsics.width, 640);
  // SR-3000: (n + 1) x 0.2 ms, max 51.2 ms.
  EXPECT_DOUBLE_EQ(ResolveCameraModel("sr3000").Info(20e6).IntegrationTimeUs(255), 51200.0);
}

TEST(CameraModelTest, UnknownModelIsNotFound) {
  try {
    (void)ResolveCameraModel("sr9000");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kNotFound);
    EXPECT_NE(std::string(e.what()).find("sr9000"), std::string::npos);
  }
  EXPECT_THROW((void)ResolveCameraModel("/nonexistent/model.yaml"), Error);
}

TEST(CameraModelTest, ErrorsNameSourceLineAndField) {
  try {
    (void)ParseCameraModel("name: X\nfull_well_e: -5\n", "m.yaml");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFormat);
    EXPECT_NE(std::string(e.what()).find("m.yaml:2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("full_well_e"), std::string::npos) << e.what();
  }
  try {
    (void)ParseCameraModel("name: X\nled_powr_w: 1\n", "m.yaml");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("led_powr_w"), std::string::npos) << e.what();
  }
  try {
    (void)ParseCameraModel("name: [unclosed\n", "m.yaml");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFormat);
    EXPECT_NE(std::string(e.what()).find("m.yaml"), std::string::npos) << e.what();
  }
  // A name the recording could not store, and a sensor larger than a recording holds (the
  // simulator used to write such files, which the reader then refused).
  const auto message = [](const std::string& yaml) {
    try {
      (void)ParseCameraModel(yaml, "m.yaml");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("(accepted)");
  };
  EXPECT_NE(message("name: " + std::string(300, 'x') + "\n").find("bytes"), std::string::npos);
  EXPECT_NE(
      message("intrinsics: {width: 4096, height: 1025, fx_px: 3000, fy_px: 3000}\n").find("pixels"),
      std::string::npos);
  EXPECT_NO_THROW((void)ParseCameraModel(
      "intrinsics: {width: 2048, height: 2048, fx_px: 1500, fy_px: 1500}\n", "m.yaml"));
  try {
    (void)ParseCameraModel("? [a, b]\n: 1\n", "m.yaml");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFormat);  // not an internal yaml-cpp error
    EXPECT_NE(std::string(e.what()).find("m.yaml"), std::string::npos) << e.what();
  }
  // A lens that folds over inside the image (tests/core/camera_intrinsics_test.cc derives the
  // fold): the simulator cannot give those pixels a ray (Embree aborted on the NaN rays).
  EXPECT_NE(message("intrinsics: {fx_px: 80, fy_px: 80, k1: -0.3, k2: 0.02}\n").find("folds over"),
            std::string::npos);
  EXPECT_THROW((void)ParseCameraModel("tap_duty: abc\n", "m.yaml"), Error);
  EXPECT_THROW((void)ParseCameraModel("default_integration_register: 300\n", "m.yaml"), Error);
  EXPECT_THROW(
      (void)ParseCameraModel(
          "scattering: [{weight: 0.6, sigma_px: 3}, {weight: 0.6, sigma_px: 4}]\n", "m.yaml"),
      Error);
}

TEST(CameraModelTest, LoadsFromFileAndKeepsDefaults) {
  const auto path = std::filesystem::temp_directory_path() /
                    ("tofcam_sim_model_test_" + std::to_string(::getpid()) + ".yaml");
  {
    std::ofstream out(path);
    out << "name: Custom\nintrinsics: {width: 32, height: 24, fx_px: 40, fy_px: 40}\nled_power_w: "
           "2\n";
  }
  const CameraModel m = ResolveCameraModel(path.string());
  EXPECT_EQ(m.name, "Custom");
  EXPECT_EQ(m.intrinsics.width, 32);
  EXPECT_DOUBLE_EQ(m.intrinsics.cx_px, 15.5);  // image centre of the new size
  EXPECT_DOUBLE_EQ(m.led_power_w, 2.0);
  EXPECT_DOUBLE_EQ(m.full_well_e, CameraModel{}.full_well_e);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace tofcam::sim

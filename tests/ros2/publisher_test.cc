// Two real processes on loopback in a DDS domain of their own: `tofcam run --ros2` on the
// simulated camera, and ros2_probe, an independent subscriber built from the same IDL with the
// plain Cyclone DDS C API. The clouds it received must be the clouds the pipeline wrote as PLY
// (--ply-every 1), bit for bit.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "loopback.h"
#include "tofcam/core/camera_intrinsics.h"

namespace tofcam::ros2_test {
namespace {

namespace fs = std::filesystem;

struct PlyPoint {
  float v[6];  // x y z amplitude intensity delta_l
  std::uint16_t flags;
};

// The binary PLY of WritePly (tofcam/io/cloud_io.h): 6 floats and a ushort per vertex.
std::vector<PlyPoint> ReadPly(const fs::path& path) {
  const std::string text = ReadText(path);
  const std::size_t end = text.find("end_header\n");
  EXPECT_NE(end, std::string::npos) << path;
  const std::size_t at = text.find("element vertex ");
  const std::size_t n = std::stoul(text.substr(at + 15));
  const char* p = text.data() + end + 11;
  EXPECT_EQ(text.size() - (end + 11), n * 26) << path;
  std::vector<PlyPoint> points(n);
  for (std::size_t i = 0; i < n; ++i, p += 26) {
    std::memcpy(points[i].v, p, 24);
    std::memcpy(&points[i].flags, p + 24, 2);
  }
  return points;
}

std::vector<double> CsvColumn(const fs::path& csv, const std::string& name) {
  std::istringstream in(ReadText(csv));
  std::string line;
  std::getline(in, line);
  int column = -1, k = 0;
  std::istringstream header(line);
  for (std::string cell; std::getline(header, cell, ','); ++k) {
    if (cell == name) column = k;
  }
  std::vector<double> values;
  while (std::getline(in, line)) {
    std::istringstream row(line);
    std::string cell;
    for (int i = 0; i <= column; ++i) std::getline(row, cell, ',');
    values.push_back(std::stod(cell));
  }
  return values;
}

TEST(Ros2Publisher, IndependentSubscriberReceivesThePipelinesClouds) {
  const int domain = ClaimDomain();
  ASSERT_GE(domain, 0) << "no free DDS domain lock in /tmp";
  UseLoopbackOnly();
  const fs::path dir = ScratchDir("publisher");
  fs::create_directories(dir / "probe");
  constexpr int kFrames = 6;
  Child probe = Spawn({TOFCAM_ROS2_PROBE, "--domain", std::to_string(domain), "--namespace",
                       "/t15/cam", "--count", std::to_string(kFrames), "--timeout-s", "60",
                       "--reliable", "1", "--out", (dir / "probe").string()},
                      (dir / "probe.log").string());
  ASSERT_GT(probe.pid, 0);
  Child run = Spawn({TOFCAM_CLI,
                     "run",
                     "--camera",
                     "sim:hand",
                     "--frames",
                     std::to_string(kFrames),
                     "--out",
                     (dir / "run").string(),
                     "--ply-every",
                     "1",
                     "--ros2",
                     "--ros2-domain",
                     std::to_string(domain),
                     "--ros2-namespace",
                     "/t15/cam",
                     "--ros2-reliable",
                     "--ros2-wait-subscribers",
                     "1",
                     "--ros2-wait-s",
                     "30"},
                    (dir / "run.log").string());
  ASSERT_GT(run.pid, 0);
  ASSERT_EQ(Wait(run), 0) << ReadText(dir / "run.log");
  ASSERT_EQ(Wait(probe), 0) << ReadText(dir / "probe.log");

  // Layout: organised 160 x 124 (SR-2), the six documented fields, 24 bytes per point.
  std::istringstream list(ReadText(dir / "probe" / "clouds.txt"));
  std::vector<std::int64_t> stamps;
  std::string line;
  const std::vector<double> timestamps_s = CsvColumn(dir / "run" / "frames.csv", "timestamp_s");
  ASSERT_EQ(timestamps_s.size(), static_cast<std::size_t>(kFrames));
  for (int k = 0; std::getline(list, line); ++k) {
    SCOPED_TRACE("cloud " + std::to_string(k));
    std::istringstream row(line);
    long long stamp;
    unsigned height, width, point_step, row_step, data_bytes;
    int dense, big;
    std::string fields;
    row >> stamp >> height >> width >> point_step >> row_step >> dense >> big >> fields >>
        data_bytes;
    EXPECT_EQ(height, 124u);
    EXPECT_EQ(width, 160u);
    EXPECT_EQ(point_step, 24u);
    EXPECT_EQ(row_step, 160u * 24u);
    EXPECT_EQ(dense, 0);
    EXPECT_EQ(big, 0);
    // PointField datatypes: FLOAT32 = 7, UINT32 = 6.
    EXPECT_EQ(fields, "x:0:7:1,y:4:7:1,z:8:7:1,amplitude:12:7:1,delta_l:16:7:1,flags:20:6:1");
    ASSERT_EQ(data_bytes, 160u * 124u * 24u);
    stamps.push_back(stamp);

    // Points: the pipeline's cloud as the run wrote it (valid points only, in pixel order);
    // every other point has NaN coordinates.
    const std::string bytes = ReadText(dir / "probe" / ("cloud_" + std::to_string(k) + ".bin"));
    ASSERT_EQ(bytes.size(), data_bytes);
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06d.ply", k);
    const std::vector<PlyPoint> ply = ReadPly(dir / "run" / name);
    ASSERT_GT(ply.size(), 1000u);
    std::size_t next = 0, nan_points = 0;
    for (std::size_t i = 0; i < 160u * 124u; ++i) {
      float v[5];
      std::uint32_t flags;
      std::memcpy(v, bytes.data() + 24 * i, 20);
      std::memcpy(&flags, bytes.data() + 24 * i + 20, 4);
      if (std::isnan(v[0])) {
        EXPECT_TRUE(std::isnan(v[1]) && std::isnan(v[2])) << i;
        ++nan_points;
        continue;
      }
      ASSERT_LT(next, ply.size()) << "more finite points than the PLY has";
      const PlyPoint& q = ply[next++];
      // Bit-exact: x y z amplitude, then delta_l (the PLY's 6th float).
      EXPECT_EQ(std::memcmp(v, q.v, 16), 0) << "point " << i;
      EXPECT_EQ(std::memcmp(&v[4], &q.v[5], 4), 0) << "delta_l of point " << i;
      EXPECT_EQ(flags, q.flags) << "flags of point " << i;
    }
    EXPECT_EQ(next, ply.size());
    EXPECT_EQ(nan_points + ply.size(), 160u * 124u);
  }
  ASSERT_EQ(stamps.size(), static_cast<std::size_t>(kFrames));
  for (int k = 1; k < kFrames; ++k) {
    EXPECT_GT(stamps[k], stamps[k - 1]);
    // Stamps advance as the frames' timestamps (frames.csv prints them to 1 µs).
    EXPECT_NEAR(static_cast<double>(stamps[k] - stamps[0]) * 1e-9,
                timestamps_s[k] - timestamps_s[0], 2e-6);
  }
  // Stamps are wall-clock time (ns since the epoch): within a day of now.
  const double now_s = static_cast<double>(std::time(nullptr));
  EXPECT_NEAR(static_cast<double>(stamps[0]) * 1e-9, now_s, 86400.0);

  // CameraInfo: the SR-2's intrinsics, no distortion (plumb_bob with zeros).
  std::istringstream info(ReadText(dir / "probe" / "camera_info.txt"));
  unsigned w, h;
  std::string model;
  info >> w >> h >> model;
  EXPECT_EQ(w, 160u);
  EXPECT_EQ(h, 124u);
  EXPECT_EQ(model, "plumb_bob");
  double k[9];
  for (double& v : k) info >> v;
  const CameraIntrinsics sr2 = CameraIntrinsics::SwissRangerSr2();
  const double expected[9] = {sr2.fx_px, 0, sr2.cx_px, 0, sr2.fy_px, sr2.cy_px, 0, 0, 1};
  for (int i = 0; i < 9; ++i) EXPECT_EQ(k[i], expected[i]) << "K[" << i << "]";
  double d;
  int nd = 0;
  while (info >> d) {
    EXPECT_EQ(d, 0.0);
    ++nd;
  }
  EXPECT_EQ(nd, 5);
  fs::remove_all(dir);
}

TEST(Ros2Publisher, RemoteCommandsSetTheRegisterAndTheSetPoint) {
  const int domain = ClaimDomain();
  ASSERT_GE(domain, 0);
  UseLoopbackOnly();
  const fs::path dir = ScratchDir("commands");
  fs::create_directories(dir / "probe");
  // The probe sends register 77 and I_A 9000 after its first cloud; the fixed controller starts
  // at c_0 = 40 and must hold 77 from some frame on.
  Child probe =
      Spawn({TOFCAM_ROS2_PROBE, "--domain", std::to_string(domain), "--namespace", "/t15/cmd",
             "--count", "3", "--timeout-s", "60", "--reliable", "1", "--send-register", "77",
             "--send-target", "9000", "--out", (dir / "probe").string()},
            (dir / "probe.log").string());
  Child run = Spawn({TOFCAM_CLI,
                     "run",
                     "--camera",
                     "sim:wall",
                     "--controller",
                     "fixed",
                     "--real-time",
                     "--frames",
                     "60",
                     "--out",
                     (dir / "run").string(),
                     "--ros2",
                     "--ros2-domain",
                     std::to_string(domain),
                     "--ros2-namespace",
                     "/t15/cmd",
                     "--ros2-reliable",
                     "--ros2-wait-subscribers",
                     "1",
                     "--ros2-wait-s",
                     "30"},
                    (dir / "run.log").string());
  ASSERT_EQ(Wait(run), 0) << ReadText(dir / "run.log");
  ASSERT_EQ(Wait(probe), 0) << ReadText(dir / "probe.log");
  const std::string log = ReadText(dir / "run.log");
  EXPECT_NE(log.find("run: remote: integration register 77 applied"), std::string::npos) << log;
  EXPECT_NE(log.find("run: remote: I_A 9000 applied"), std::string::npos) << log;
  const std::vector<double> registers =
      CsvColumn(dir / "run" / "frames.csv", "integration_register");
  ASSERT_EQ(registers.size(), 60u);
  EXPECT_EQ(registers.front(), 40);
  EXPECT_EQ(registers.back(), 77);
  int switches = 0;
  for (std::size_t i = 1; i < registers.size(); ++i) {
    EXPECT_TRUE(registers[i] == 40 || registers[i] == 77) << registers[i];
    switches += registers[i] != registers[i - 1];
  }
  EXPECT_EQ(switches, 1);
  EXPECT_NE(ReadText(dir / "run" / "summary.json").find("\"ros2_commands_applied\": 2"),
            std::string::npos);
  fs::remove_all(dir);
}

TEST(Ros2Publisher, StampsIncreaseWhenTheSourcesTimestampsDoNot) {
  // A looping single-frame import repeats timestamp 0: the stamps must still increase.
  const int domain = ClaimDomain();
  ASSERT_GE(domain, 0);
  UseLoopbackOnly();
  const fs::path dir = ScratchDir("loop");
  fs::create_directories(dir / "probe");
  Child probe = Spawn(
      {TOFCAM_ROS2_PROBE, "--domain", std::to_string(domain), "--namespace", "/t15/loop", "--count",
       "4", "--timeout-s", "60", "--reliable", "1", "--out", (dir / "probe").string()},
      (dir / "probe.log").string());
  Child run =
      Spawn({TOFCAM_CLI, "run", "--camera",
             "import:azure-kinect:" + std::string(TOFCAM_TEST_DATA_DIR) + "/real/azure_kinect",
             "--loop", "--frames", "4", "--out", (dir / "run").string(), "--ros2", "--ros2-domain",
             std::to_string(domain), "--ros2-namespace", "/t15/loop", "--ros2-reliable",
             "--ros2-wait-subscribers", "1", "--ros2-wait-s", "30"},
            (dir / "run.log").string());
  ASSERT_EQ(Wait(run), 0) << ReadText(dir / "run.log");
  ASSERT_EQ(Wait(probe), 0) << ReadText(dir / "probe.log");
  EXPECT_EQ(CsvColumn(dir / "run" / "frames.csv", "timestamp_s"),
            std::vector<double>(4, 0.0));  // the source's timestamps: all 0
  std::istringstream list(ReadText(dir / "probe" / "clouds.txt"));
  std::vector<long long> stamps;
  for (std::string line; std::getline(list, line);) stamps.push_back(std::stoll(line));
  ASSERT_EQ(stamps.size(), 4u);
  for (int k = 1; k < 4; ++k) EXPECT_GT(stamps[k], stamps[k - 1]);
  fs::remove_all(dir);
}

TEST(Ros2Publisher, NoSubscriberIsAClearTimeoutNotAHang) {
  const int domain = ClaimDomain();
  ASSERT_GE(domain, 0);
  UseLoopbackOnly();
  const fs::path dir = ScratchDir("nosub");
  Child run = Spawn(
      {TOFCAM_CLI, "run", "--camera", "sim:wall", "--frames", "2", "--out", (dir / "run").string(),
       "--ros2", "--ros2-domain", std::to_string(domain), "--ros2-namespace", "/t15/nobody",
       "--ros2-wait-subscribers", "1", "--ros2-wait-s", "0.5"},
      (dir / "run.log").string());
  const int status = Wait(run);
  const std::string log = ReadText(dir / "run.log");
  EXPECT_NE(status, 0) << log;
  EXPECT_NE(status, -1) << "killed: it hung";
  EXPECT_NE(log.find("subscriber(s) of rt/t15/nobody/*"), std::string::npos) << log;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tofcam::ros2_test

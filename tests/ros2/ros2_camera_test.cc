// The ROS 2 camera source: spec parsing in process, then two real processes on loopback in a DDS
// domain of their own: ros2_replay publishes the recorded Azure Kinect frame as the Azure Kinect
// ROS 2 driver does, `tofcam run --camera ros2:...?driver=azure-kinect` processes it, and the
// results must equal those of the same frame through `import:azure-kinect:`.
#include "tofcam/ros2/ros2_camera.h"

#include <dds/dds.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "loopback.h"
#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/Image.h"
#include "tofcam/core/error.h"

namespace tofcam::ros2_test {
namespace {

namespace fs = std::filesystem;
using ros2::ParseRos2CameraSpec;
using ros2::Ros2CameraOptions;

const std::string kAzure = std::string(TOFCAM_TEST_DATA_DIR) + "/real/azure_kinect";

TEST(Ros2CameraSpec, DriversAndOverrides) {
  Ros2CameraOptions o = ParseRos2CameraSpec("/k4a?driver=azure-kinect", 7);
  EXPECT_EQ(o.domain_id, 7);
  EXPECT_EQ(o.name_space, "/k4a");
  EXPECT_EQ(ros2::ResolveTopic(o.name_space, o.depth_topic), "/k4a/depth/image_raw");
  EXPECT_EQ(ros2::ResolveTopic(o.name_space, o.amplitude_topic), "/k4a/ir/image_raw");
  EXPECT_EQ(ros2::ResolveTopic(o.name_space, o.camera_info_topic), "/k4a/depth/camera_info");
  EXPECT_FALSE(o.frame.depth_is_radial);
  EXPECT_EQ(o.frame.model, "Azure Kinect");

  o = ParseRos2CameraSpec("ifm3d/camera?driver=ifm3d&amplitude=/other/amp&domain=3&timeout_s=2", 0);
  EXPECT_EQ(o.name_space, "/ifm3d/camera");
  EXPECT_EQ(ros2::ResolveTopic(o.name_space, o.depth_topic), "/ifm3d/camera/distance");
  EXPECT_EQ(ros2::ResolveTopic(o.name_space, o.amplitude_topic), "/other/amp");
  EXPECT_TRUE(o.frame.depth_is_radial);
  EXPECT_EQ(o.frame.range_m, 32.768);
  EXPECT_EQ(o.domain_id, 3);
  EXPECT_EQ(o.timeout_s, 2.0);

  o = ParseRos2CameraSpec("", 0);  // tofcam's own topics in "/"
  EXPECT_EQ(ros2::ResolveTopic(o.name_space, o.depth_topic), "/depth");
  EXPECT_TRUE(o.intensity_topic.empty());

  for (const char* bad :
       {"/x?driver=kinect2", "/x?colour=1", "/x?timeout_s=abc", "/x?depth_axis=y", "/x?domain=999",
        "/x?timeout_s=0", "/x?depth", "/x?reliable=yes", "/bad//ns"}) {
    try {
      (void)ParseRos2CameraSpec(bad, 0);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument) << bad << ": " << e.what();
    }
  }
}

TEST(Ros2Camera, MissingPublisherIsAClearTimeout) {
  const int domain = ClaimDomain();
  ASSERT_GE(domain, 0);
  UseLoopbackOnly();
  try {
    ros2::Ros2Camera camera(ParseRos2CameraSpec("/t15/nobody?timeout_s=0.3", domain));
    ADD_FAILURE() << "opened a camera nobody publishes";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kNotFound);
    EXPECT_NE(std::string(e.what()).find("no CameraInfo on /t15/nobody/camera_info within 0.3 s"),
              std::string::npos)
        << e.what();
  }
}

// In-process writers of a 2 x 1 camera's topics, to drive Ros2Camera sample by sample.
class TinyDriver {
 public:
  TinyDriver(int domain, const std::string& ns) {
    participant_ = dds_create_participant(domain, nullptr, nullptr);
    dds_qos_t* qos = dds_create_qos();
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 16);
    auto writer = [&](const dds_topic_descriptor_t* d, const std::string& name) {
      return dds_create_writer(
          participant_,
          dds_create_topic(participant_, d, ("rt" + ns + "/" + name).c_str(), nullptr, nullptr),
          qos, nullptr);
    };
    depth_ = writer(&sensor_msgs_msg_dds__Image__desc, "depth");
    amplitude_ = writer(&sensor_msgs_msg_dds__Image__desc, "amplitude");
    info_ = writer(&sensor_msgs_msg_dds__CameraInfo__desc, "camera_info");
    dds_delete_qos(qos);
  }
  ~TinyDriver() { dds_delete(participant_); }

  bool WaitForReader() {
    for (int i = 0; i < 1000; ++i) {
      int matched = 0;
      for (dds_entity_t w : {depth_, amplitude_, info_}) {
        dds_publication_matched_status_t st{};
        dds_get_publication_matched_status(w, &st);
        matched += st.current_count > 0;
      }
      if (matched == 3) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  }
  void Info() {
    sensor_msgs_msg_dds__CameraInfo_ m{};
    m.header.frame_id = frame_id_;
    m.width = 2;
    m.height = 1;
    m.distortion_model = model_;
    const double k[9] = {1, 0, 0.5, 0, 1, 0, 0, 0, 1};
    std::memcpy(m.k, k, sizeof k);
    dds_write(info_, &m);
  }
  // A 16UC1 image with both pixels = value on depth (true) or amplitude (false).
  void Image(bool depth, std::int32_t stamp_s, std::uint16_t value) {
    std::uint16_t px[2] = {value, value};
    sensor_msgs_msg_dds__Image_ m{};
    m.header.stamp.sec = stamp_s;
    m.header.frame_id = frame_id_;
    m.width = 2;
    m.height = 1;
    m.encoding = encoding_;
    m.step = 4;
    m.data = {4, 4, reinterpret_cast<std::uint8_t*>(px), false};
    dds_write(depth ? depth_ : amplitude_, &m);
  }
  void Flush() {
    for (dds_entity_t w : {depth_, amplitude_, info_}) dds_wait_for_acks(w, DDS_SECS(5));
  }

 private:
  char frame_id_[4] = "cam";
  char model_[10] = "plumb_bob";
  char encoding_[6] = "16UC1";
  dds_entity_t participant_ = 0, depth_ = 0, amplitude_ = 0, info_ = 0;
};

TEST(Ros2Camera, PairsImagesByStampAndCountsTheUnpaired) {
  const int domain = ClaimDomain();
  ASSERT_GE(domain, 0);
  UseLoopbackOnly();
  TinyDriver driver(domain, "/t15/tiny");
  std::thread info_sender([&] {
    ASSERT_TRUE(driver.WaitForReader());
    driver.Info();
    // Stamp 1: depth only (its amplitude is lost). Stamp 2: both, amplitude first. Stamp 3:
    // both.
    driver.Image(true, 1, 1000);
    driver.Image(false, 2, 300);
    driver.Image(true, 2, 2000);
    driver.Image(true, 3, 3000);
    driver.Image(false, 3, 400);
    driver.Flush();
  });
  std::optional<Frame> f2, f3, end;
  std::uint64_t skipped = 0;
  std::string last_skip;
  try {
    ros2::Ros2Camera camera(ParseRos2CameraSpec("/t15/tiny?reliable=1&timeout_s=5", domain));
    EXPECT_EQ(camera.Info().width(), 2);
    f2 = camera.Grab();
    f3 = camera.Grab();
    skipped = camera.skipped();
    last_skip = camera.last_skip();
    info_sender.join();
  } catch (...) {
    info_sender.join();
    throw;
  }
  ASSERT_TRUE(f2.has_value());
  ASSERT_TRUE(f3.has_value());
  // Registers = 8 x radial mm; the rays of pixels at u = 0, 1 with cx = 0.5, fx = 1 have
  // z = 1 / sqrt(1.25).
  EXPECT_EQ(f2->distance[0], static_cast<std::uint16_t>(std::lround(8 * 2000 * std::sqrt(1.25))));
  EXPECT_EQ(f2->amplitude[0], 300);
  EXPECT_EQ(f3->distance[1], static_cast<std::uint16_t>(std::lround(8 * 3000 * std::sqrt(1.25))));
  EXPECT_EQ(f3->amplitude[1], 400);
  EXPECT_EQ(f2->info.timestamp_ns, 0);
  EXPECT_EQ(f3->info.timestamp_ns, 1'000'000'000);
  EXPECT_EQ(f2->info.sequence, 0u);
  EXPECT_EQ(f3->info.sequence, 1u);
  EXPECT_EQ(skipped, 1u);
  EXPECT_NE(last_skip.find("/t15/tiny/depth: image without a partner"), std::string::npos)
      << last_skip;
}

// A publisher that restarts (stamps going back) must not give frames whose timestamps
// decrease (a recording refuses them, `run` wrote negative times): the older frame is skipped
// and counted, and the stream goes on with the next newer one. Then Interrupt() ends a Grab()
// that waits for a silent publisher long before its 30 s timeout (how `view` and `run` stop).
TEST(Ros2Camera, OlderStampsAreSkippedAndInterruptEndsAWaitingGrab) {
  const int domain = ClaimDomain();
  ASSERT_GE(domain, 0);
  UseLoopbackOnly();
  TinyDriver driver(domain, "/t15/back");
  std::atomic<bool> first_served{false};
  std::thread sender([&] {
    ASSERT_TRUE(driver.WaitForReader());
    driver.Info();
    driver.Image(true, 5, 5000);
    driver.Image(false, 5, 500);
    driver.Flush();
    for (int i = 0; i < 1000 && !first_served.load(); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    driver.Image(true, 3, 3000);  // before the frame served: skipped
    driver.Image(false, 3, 300);
    driver.Image(true, 6, 6000);
    driver.Image(false, 6, 600);
    driver.Flush();
  });
  std::optional<Frame> f5, f6, end;
  std::uint64_t skipped = 0;
  std::string last_skip;
  double waited_s = 0;
  try {
    ros2::Ros2Camera camera(ParseRos2CameraSpec("/t15/back?reliable=1&timeout_s=30", domain));
    f5 = camera.Grab();
    first_served = true;
    f6 = camera.Grab();
    skipped = camera.skipped();
    last_skip = camera.last_skip();
    sender.join();
    std::thread stopper([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(300));
      camera.Interrupt();
    });
    const auto t0 = std::chrono::steady_clock::now();
    end = camera.Grab();
    waited_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    stopper.join();
  } catch (...) {
    if (sender.joinable()) sender.join();
    throw;
  }
  ASSERT_TRUE(f5.has_value());
  ASSERT_TRUE(f6.has_value());
  EXPECT_EQ(f5->amplitude[0], 500);
  EXPECT_EQ(f6->amplitude[0], 600);
  EXPECT_EQ(f6->info.timestamp_ns, 1'000'000'000);  // 6 s - 5 s
  EXPECT_EQ(skipped, 1u);
  EXPECT_NE(last_skip.find("not after the previous frame"), std::string::npos) << last_skip;
  EXPECT_FALSE(end.has_value());
  // The Grab waits in slices of 0.5 s; 10 s leaves room for a loaded machine and is a third of
  // the timeout the wait would otherwise have run to.
  EXPECT_LT(waited_s, 10.0);
}

struct RunOutput {
  int status = -1;
  std::string log;
  fs::path dir;
};

// Writes a config that fixes the ΔL scale, so both sources use the same one.
fs::path Config(const fs::path& dir) {
  const fs::path p = dir / "config.yaml";
  std::ofstream(p) << "accuracy:\n  scale: 0.5\n";
  return p;
}

RunOutput RunImport(const fs::path& dir) {
  RunOutput r;
  r.dir = dir / "import";
  Child c = Spawn({TOFCAM_CLI, "run", "--camera", "import:azure-kinect:" + kAzure, "--frames", "1",
                   "--config", Config(dir).string(), "--ply-every", "1", "--out", r.dir.string()},
                  (dir / "import.log").string());
  r.status = Wait(c);
  r.log = ReadText(dir / "import.log");
  return r;
}

// `tofcam run --camera ros2:` against ros2_replay with `replay_args`.
RunOutput RunRos2(const fs::path& dir, const std::string& name, int frames,
                  const std::vector<std::string>& replay_args, int* replay_status) {
  const int domain = ClaimDomain();
  UseLoopbackOnly();
  const std::string ns = "/t15/" + name;
  RunOutput r;
  r.dir = dir / name;
  Child run = Spawn(
      {TOFCAM_CLI, "run", "--camera", "ros2:" + ns + "?driver=azure-kinect&reliable=1&timeout_s=20",
       "--ros2-domain", std::to_string(domain), "--frames", std::to_string(frames), "--config",
       Config(dir).string(), "--ply-every", "1", "--out", r.dir.string()},
      (dir / (name + ".log")).string());
  std::vector<std::string> args = {TOFCAM_ROS2_REPLAY,
                                   "--domain",
                                   std::to_string(domain),
                                   "--namespace",
                                   ns,
                                   "--azure-dir",
                                   kAzure,
                                   "--wait-s",
                                   "20"};
  args.insert(args.end(), replay_args.begin(), replay_args.end());
  Child replay = Spawn(args, (dir / (name + "_replay.log")).string());
  r.status = Wait(run);
  *replay_status = Wait(replay);
  r.log = ReadText(dir / (name + ".log")) + ReadText(dir / (name + "_replay.log"));
  return r;
}

// frames.csv rows without the frame, sequence and timestamp columns.
std::vector<std::string> Rows(const fs::path& csv) {
  std::istringstream in(ReadText(csv));
  std::vector<std::string> rows;
  std::string line;
  std::getline(in, line);
  while (std::getline(in, line)) {
    std::size_t at = 0;
    for (int i = 0; i < 3; ++i) at = line.find(',', at) + 1;
    std::string rest = line.substr(at);
    rest = rest.substr(0, rest.rfind(','));  // elapsed_s
    rows.push_back(rest);
  }
  return rows;
}

TEST(Ros2Camera, ReplayedRealFramesGiveTheImportersResults) {
  const fs::path dir = ScratchDir("camera");
  const RunOutput import = RunImport(dir);
  ASSERT_EQ(import.status, 0) << import.log;
  int replay_status = -1;
  const RunOutput ros = RunRos2(dir, "azure", 3, {"--frames", "3"}, &replay_status);
  ASSERT_EQ(ros.status, 0) << ros.log;
  EXPECT_EQ(replay_status, 0) << ros.log;

  const std::string expected_ply = ReadText(import.dir / "frame_000000.ply");
  ASSERT_GT(expected_ply.size(), 100000u);
  const std::vector<std::string> expected_row = Rows(import.dir / "frames.csv");
  ASSERT_EQ(expected_row.size(), 1u);
  const std::vector<std::string> rows = Rows(ros.dir / "frames.csv");
  ASSERT_EQ(rows.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    SCOPED_TRACE("frame " + std::to_string(k));
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06d.ply", k);
    EXPECT_TRUE(ReadText(ros.dir / name) == expected_ply) << "clouds differ";
    EXPECT_EQ(rows[k], expected_row[0]);
  }
  const nlohmann::json summary = nlohmann::json::parse(ReadText(ros.dir / "summary.json"));
  EXPECT_EQ(summary["camera_model"], "Azure Kinect");
  EXPECT_EQ(summary["source_skipped_samples"], 0);
  // Stamps 1/30 s apart (ros2_replay) became the frames' timestamps.
  EXPECT_NEAR(summary["camera_frames_per_s"].get<double>(), 30.0, 1e-6);
  fs::remove_all(dir);
}

TEST(Ros2Camera, MalformedSamplesAreSkippedAndCounted) {
  const fs::path dir = ScratchDir("malformed");
  const RunOutput import = RunImport(dir);
  ASSERT_EQ(import.status, 0) << import.log;
  const std::string expected_ply = ReadText(import.dir / "frame_000000.ply");
  for (const std::string kind : {"encoding", "step"}) {
    SCOPED_TRACE(kind);
    int replay_status = -1;
    // Frame 1 of 4 is malformed: the run gets the other 3.
    const RunOutput ros =
        RunRos2(dir, "bad_" + kind, 3, {"--frames", "4", "--bad-at", "1", "--bad-kind", kind},
                &replay_status);
    ASSERT_EQ(ros.status, 0) << ros.log;
    const nlohmann::json summary = nlohmann::json::parse(ReadText(ros.dir / "summary.json"));
    EXPECT_EQ(summary["frames"], 3);
    EXPECT_EQ(summary["source_skipped_samples"], 1);
    const std::string why = summary["source_last_skip"];
    EXPECT_NE(why.find("/t15/bad_" + kind + "/depth/image_raw: "), std::string::npos) << why;
    EXPECT_NE(why.find(kind == "encoding" ? "encoding 'bgr8' is not one of 16UC1, 32FC1"
                                          : "data holds 737280 bytes, step x height = 738432"),
              std::string::npos)
        << why;
    EXPECT_NE(ros.log.find("warning: the ROS 2 source skipped 1 sample(s)"), std::string::npos)
        << ros.log;
    for (int k = 0; k < 3; ++k) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%06d.ply", k);
      EXPECT_TRUE(ReadText(ros.dir / name) == expected_ply) << "frame " << k;
    }
  }
  fs::remove_all(dir);
}

TEST(Ros2Camera, NanIntrinsicsAreAClearError) {
  const fs::path dir = ScratchDir("nan");
  int replay_status = -1;
  const RunOutput ros =
      RunRos2(dir, "nan", 1, {"--frames", "1", "--nan-intrinsics", "1"}, &replay_status);
  EXPECT_NE(ros.status, 0) << ros.log;
  EXPECT_NE(ros.status, -1) << "killed: it hung";
  EXPECT_NE(ros.log.find("/t15/nan/depth/camera_info: k[0] is nan"), std::string::npos) << ros.log;
  fs::remove_all(dir);
}

TEST(Ros2Camera, MissingPublisherIsAClearCliError) {
  const int domain = ClaimDomain();
  UseLoopbackOnly();
  const fs::path dir = ScratchDir("cli_nobody");
  Child run =
      Spawn({TOFCAM_CLI, "run", "--camera", "ros2:/t15/nobody?timeout_s=0.5", "--ros2-domain",
             std::to_string(domain), "--frames", "1", "--out", (dir / "out").string()},
            (dir / "run.log").string());
  const int status = Wait(run);
  const std::string log = ReadText(dir / "run.log");
  EXPECT_NE(status, 0) << log;
  EXPECT_NE(status, -1) << "killed: it hung";
  EXPECT_NE(log.find("no CameraInfo on /t15/nobody/camera_info within 0.5 s in DDS domain " +
                     std::to_string(domain)),
            std::string::npos)
      << log;
  fs::remove_all(dir);
}

TEST(Ros2Camera, RefusesToReadWhatTheSameRunPublishes) {
  const fs::path dir = ScratchDir("feedback");
  Child run = Spawn({TOFCAM_CLI, "run", "--camera", "ros2:/t15/same", "--frames", "1", "--out",
                     (dir / "out").string(), "--ros2", "--ros2-namespace", "/t15/same"},
                    (dir / "run.log").string());
  const int status = Wait(run);
  const std::string log = ReadText(dir / "run.log");
  EXPECT_NE(status, 0) << log;
  EXPECT_NE(status, -1) << "killed: it hung";
  EXPECT_NE(log.find("reads /t15/same/depth, inside --ros2-namespace /t15/same"), std::string::npos)
      << log;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tofcam::ros2_test

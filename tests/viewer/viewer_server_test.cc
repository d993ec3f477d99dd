// The viewer's server on loopback (issue 17): hostile and malformed requests get 4xx and leave the
// camera loop running; controls apply to the next frame; frames are the documented binary.
#include "viewer_server.h"

#include <gtest/gtest.h>
#include <httplib.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "tofcam/io/recording.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::viewer {
namespace {

using json = nlohmann::json;

std::unique_ptr<Camera> OpenSim(const std::string& spec) {
  if (spec.rfind("sim:", 0) != 0) throw Error(ErrorCode::kInvalidArgument, "not sim: " + spec);
  auto [name, overrides] = sim::ParseSceneSpec(spec.substr(4));
  return std::make_unique<sim::SimulatedCamera>(
      sim::ResolveScene(name, overrides), sim::ResolveCameraModel("sr2"), sim::SimulatorOptions{});
}

class ViewerServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ViewerOptions o;
    o.port = 0;
    o.camera_spec = "sim:hand";
    // Per process and test, removed in TearDown (recordings made by the tests go there).
    record_dir_ = ::testing::TempDir() + "tofcam_view_test_" + std::to_string(::getpid()) + "_" +
                  ::testing::UnitTest::GetInstance()->current_test_info()->name();
    o.record_dir = record_dir_;
    PipelineOptions p;
    server_ = std::make_unique<ViewerServer>(o, p, OpenSim);
    server_->Start();
    client_ = std::make_unique<httplib::Client>("127.0.0.1", server_->port());
    client_->set_read_timeout(5, 0);
    WaitFrames(2);
  }
  void TearDown() override {
    server_->Stop();
    std::error_code ignored;  // a failed removal must not hide the test's own result
    std::filesystem::remove_all(record_dir_, ignored);
  }

  // Waits (bounded) until the loop has processed `more` further frames; false on timeout.
  bool WaitFrames(long long more) {
    const long long target = server_->Status().frames + more;
    for (int k = 0; k < 500; ++k) {
      if (server_->Status().frames >= target) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  }
  // The next frame the server sends: its size and its planes ("distance_m", "delta_l_m",
  // "flags", ...) by name, as raw bytes.
  struct SentFrame {
    int width = 0, height = 0;
    std::map<std::string, std::string> planes;
    // A plane as values of T (empty when the frame has no such plane).
    template <typename T>
    std::vector<T> Plane(const std::string& name) const {
      const auto it = planes.find(name);
      if (it == planes.end()) return {};
      std::vector<T> values(it->second.size() / sizeof(T));
      std::memcpy(values.data(), it->second.data(), values.size() * sizeof(T));
      return values;
    }
  };
  SentFrame NextFrame() {
    SentFrame f;
    const auto r = client_->Get("/frame?after=" + std::to_string(server_->Status().frames));
    EXPECT_TRUE(r && r->status == 200);
    if (!r || r->status != 200) return f;
    std::uint32_t prefix[3];
    std::memcpy(prefix, r->body.data(), 12);
    const json h = json::parse(r->body.substr(12, prefix[2]));
    f.width = h.at("width");
    f.height = h.at("height");
    for (const json& p : h.at("planes")) {
      f.planes[p.at("name")] = r->body.substr(12 + prefix[2] + p.at("offset").get<std::size_t>(),
                                              p.at("bytes").get<std::size_t>());
    }
    return f;
  }

  int Post(const std::string& body, std::string* reply = nullptr) {
    const auto r = client_->Post("/control", body, "application/json");
    if (!r) return -1;
    if (reply) *reply = r->body;
    return r->status;
  }

  std::string record_dir_;
  std::unique_ptr<ViewerServer> server_;
  std::unique_ptr<httplib::Client> client_;
};

TEST_F(ViewerServerTest, HostileRequestsGet4xxAndTheLoopRuns) {
  std::string reply;
  EXPECT_EQ(Post("{not json", &reply), 400);
  EXPECT_NE(reply.find("not valid JSON"), std::string::npos) << reply;
  EXPECT_EQ(Post("[1, 2]"), 400);
  EXPECT_EQ(Post(R"({"target_intensity": -5})", &reply), 400);
  EXPECT_NE(reply.find("target_intensity"), std::string::npos) << reply;
  EXPECT_EQ(Post(R"({"target_intensity": "high"})"), 400);
  EXPECT_EQ(Post(R"({"max_delta_l_m": 1e308})"), 400);
  EXPECT_EQ(Post(R"({"fixed_register": 100000})"), 400);
  EXPECT_EQ(Post(R"({"controller": "pid"})"), 400);
  EXPECT_EQ(Post(R"({"filters": {"accuracy": 1}})"), 400);
  EXPECT_EQ(Post(R"({"filters": {"magic": true}})"), 400);
  EXPECT_EQ(Post(R"({"no_such_control": 1})", &reply), 400);
  EXPECT_NE(reply.find("no_such_control"), std::string::npos) << reply;
  EXPECT_EQ(Post(R"({"scene": {"Bad Name": 1}})"), 400);
  EXPECT_EQ(Post(R"({"scene": {"no_such_parameter": 1}})", &reply), 400);
  EXPECT_EQ(Post(R"({"record": "maybe"})"), 400);
  // A refused control changes nothing, even its valid parts.
  EXPECT_EQ(Post(R"({"paused": true, "target_intensity": -1})"), 400);
  EXPECT_FALSE(server_->Status().paused);
  // Huge body: refused before it is read into a control.
  EXPECT_EQ(Post(std::string(200 * 1024, 'a')), 413);
  // Routes that do not exist, path traversal, bad query values.
  for (const char* path : {"/nope", "/../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd",
                           "/viewer.js/../../../etc/passwd", "/web/index.html"}) {
    const auto r = client_->Get(path);
    ASSERT_TRUE(r) << path;
    EXPECT_EQ(r->status, 404) << path;
  }
  EXPECT_EQ(client_->Get("/frame?after=-3")->status, 400);
  EXPECT_EQ(client_->Get("/frame?after=abc")->status, 400);
  EXPECT_EQ(client_->Get("/frame?client=" + std::string(100, 'x'))->status, 400);
  EXPECT_EQ(client_->Get("/frame?client=a/b")->status, 400);
  // Another site's page, or a DNS name that is not this server.
  EXPECT_EQ(client_->Get("/status", {{"Origin", "http://evil.example"}})->status, 403);
  EXPECT_EQ(client_->Get("/status", {{"Host", "evil.example"}})->status, 403);
  EXPECT_EQ(client_
                ->Post("/control", {{"Origin", "http://evil.example"}}, R"({"paused": true})",
                       "application/json")
                ->status,
            403);
  EXPECT_FALSE(server_->Status().paused);
  // The same page's origin is fine.
  const std::string self = "http://127.0.0.1:" + std::to_string(server_->port());
  EXPECT_EQ(client_->Get("/status", {{"Origin", self}})->status, 200);
  // Through all of that the camera loop kept running.
  EXPECT_TRUE(WaitFrames(3));
}

TEST_F(ViewerServerTest, FramesAreTheDocumentedBinaryAndSkippedFramesAreCounted) {
  const auto r = client_->Get("/frame?after=0&client=t");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200);
  const std::string& b = r->body;
  ASSERT_GT(b.size(), 12u);
  std::uint32_t prefix[3];
  std::memcpy(prefix, b.data(), 12);
  EXPECT_EQ(prefix[0], 0x56464f54u);  // "TOFV"
  EXPECT_EQ(prefix[1], 1u);
  const json h = json::parse(b.substr(12, prefix[2]));
  const std::size_t base = 12 + prefix[2];
  EXPECT_EQ(base % 8, 0u);
  const int n = h.at("width").get<int>() * h.at("height").get<int>();
  const sim::CameraModel sr2 = sim::ResolveCameraModel("sr2");
  const CameraInfo info = sr2.Info(sr2.modulation_frequencies_hz.front());
  EXPECT_EQ(n, info.width() * info.height());
  std::map<std::string, std::size_t> bytes;
  for (const json& p : h.at("planes")) {
    const std::size_t offset = p.at("offset"), size = p.at("bytes");
    EXPECT_EQ(offset % 4, 0u);
    EXPECT_LE(base + offset + size, b.size());
    bytes[p.at("name")] = size;
  }
  EXPECT_EQ(bytes.at("raw_rgb"), 3u * n);
  EXPECT_EQ(bytes.at("filtered_rgb"), 3u * n);
  EXPECT_EQ(bytes.at("distance_m"), 4u * n);
  EXPECT_EQ(bytes.at("flags"), 2u * n);
  EXPECT_EQ(bytes.at("error_m"), 4u * n);  // the simulator has truth
  // A client that asks again after the loop moved on has skipped those frames: counted.
  const long long seq = h.at("seq");
  ASSERT_TRUE(WaitFrames(4));
  const auto again = client_->Get("/frame?after=" + std::to_string(seq) + "&client=t");
  ASSERT_TRUE(again);
  std::memcpy(prefix, again->body.data(), 12);
  const long long seq2 = json::parse(again->body.substr(12, prefix[2])).at("seq");
  EXPECT_GE(seq2, seq + 4);
  EXPECT_GE(server_->Status().dropped, seq2 - seq - 1);
  // Nothing newer within the wait: 204, not a stale frame.
  ASSERT_EQ(server_->ApplyControl(R"({"paused": true})"), "");
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const auto latest = client_->Get("/frame?after=0");
  ASSERT_TRUE(latest && latest->status == 200);
  std::memcpy(prefix, latest->body.data(), 12);
  const json latest_header = json::parse(latest->body.substr(12, prefix[2]));
  const long long newest = latest_header.at("seq");
  EXPECT_EQ(client_->Get("/frame?after=" + std::to_string(newest))->status, 204);
  // A frame number this server never sent (a page of an earlier server on the port) gets the
  // latest frame at once, with this server's session, which /meta reports too.
  const auto t0 = std::chrono::steady_clock::now();
  const auto stale = client_->Get("/frame?after=" + std::to_string(newest + 1000));
  ASSERT_TRUE(stale);
  EXPECT_EQ(stale->status, 200);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(1500));
  const std::string session = json::parse(client_->Get("/meta")->body).at("session");
  EXPECT_FALSE(session.empty());
  EXPECT_EQ(latest_header.at("session"), session);
  EXPECT_EQ(latest_header.at("last_error"), "");
}

TEST_F(ViewerServerTest, ControlsApplyToTheNextFrames) {
  std::string reply;
  // The hand scene at the default exposure: the accuracy filter removes the noisy far pixels;
  // off, the kept set is a superset (every other filter unchanged), so valid rises.
  ASSERT_TRUE(WaitFrames(3));
  const double with = server_->Status().valid_fraction;
  ASSERT_EQ(Post(R"({"filters": {"accuracy": false}})"), 200);
  ASSERT_TRUE(WaitFrames(3));
  const double without = server_->Status().valid_fraction;
  EXPECT_GT(without, with);
  // Pause holds the loop (the cloud of the last frame is still there); step runs exactly the
  // frames asked for.
  ASSERT_EQ(Post(R"({"paused": true})"), 200);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const long long held = server_->Status().frames;
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(server_->Status().frames, held);
  const auto paused_ply = client_->Get("/cloud.ply");
  ASSERT_TRUE(paused_ply);
  EXPECT_EQ(paused_ply->status, 200);
  ASSERT_EQ(Post(R"({"step": 2})"), 200);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  EXPECT_EQ(server_->Status().frames, held + 2);
  ASSERT_EQ(Post(R"({"paused": false, "fixed_register": 20})"), 200);
  ASSERT_TRUE(WaitFrames(3));
  EXPECT_EQ(server_->Status().controller, "fixed");
  // Scene parameters reopen the simulator: the hand moves from 0.2 to 0.6 m, and a pixel at
  // the image centre (on the hand in both) reads about 0.4 m further.
  const auto centre_distance = [&] {
    const SentFrame frame = NextFrame();
    const std::vector<float> d = frame.Plane<float>("distance_m");
    const std::size_t centre =
        static_cast<std::size_t>(frame.height / 2) * static_cast<std::size_t>(frame.width) +
        static_cast<std::size_t>(frame.width / 2);
    return centre < d.size() ? static_cast<double>(d[centre]) : -1.0;
  };
  const double near = centre_distance();
  ASSERT_EQ(Post(R"({"scene": {"hand_distance_m": 0.6}})", &reply), 200) << reply;
  ASSERT_TRUE(WaitFrames(3));
  const double far = centre_distance();
  EXPECT_NEAR(far - near, 0.4, 0.1) << near << " -> " << far;
  // The pan unit turns.
  ASSERT_EQ(Post(R"({"pan_deg": 10})"), 200);
  // The cloud as PLY.
  const auto ply = client_->Get("/cloud.ply");
  ASSERT_TRUE(ply);
  EXPECT_EQ(ply->status, 200);
  EXPECT_EQ(ply->body.rfind("ply\n", 0), 0u);
  // Recording to HDF5 starts and stops.
  ASSERT_EQ(Post(R"({"record": "start"})"), 200);
  ASSERT_TRUE(WaitFrames(3));
  const std::string path = server_->Status().recording;
  EXPECT_FALSE(path.empty()) << server_->Status().last_error;
  // Other scene parameters while recording: a new simulator, whose clock starts again, so the
  // file is finished and a second one begun (one file would have decreasing timestamps).
  ASSERT_EQ(Post(R"({"scene": {"hand_distance_m": 0.5}})", &reply), 200) << reply;
  ASSERT_TRUE(WaitFrames(3));
  const std::string second = server_->Status().recording;
  EXPECT_FALSE(second.empty()) << server_->Status().last_error;
  EXPECT_NE(second, path);
  ASSERT_EQ(Post(R"({"record": "stop"})"), 200);
  ASSERT_TRUE(WaitFrames(2));
  EXPECT_TRUE(server_->Status().recording.empty());
  EXPECT_EQ(server_->Status().last_error.find("recording"), std::string::npos)
      << server_->Status().last_error;
  for (const std::string& file : {path, second}) {
    const RecordingReader reader(file);  // refuses decreasing timestamps
    EXPECT_GE(reader.frame_count(), 1u) << file;
  }
}

TEST_F(ViewerServerTest, StepsNeedAPauseAndRefusalsAreImmediate) {
  std::string reply;
  // While running, steps would pile up and run on after the next pause.
  EXPECT_EQ(Post(R"({"step": 1000})", &reply), 400);
  EXPECT_NE(reply.find("paused"), std::string::npos) << reply;
  ASSERT_EQ(Post(R"({"paused": true, "step": 1})"), 200);  // one request: fine
  ASSERT_EQ(Post(R"({"paused": false})"), 200);
  // Numbers beyond 2^63 are named as sent, not as a wrapped negative number.
  EXPECT_EQ(Post(R"({"bias_register": 18446744073709551615})", &reply), 400);
  EXPECT_NE(reply.find("18446744073709551615"), std::string::npos) << reply;
  // A recording directory that cannot be written: refused at once (the page used to show
  // "recording" while the loop had failed).
  { std::ofstream(record_dir_) << "a file, not a directory"; }
  EXPECT_EQ(Post(R"({"record": "start"})", &reply), 400);
  EXPECT_NE(reply.find("recording"), std::string::npos) << reply;
}

// A camera without a pan unit (a stand-in for a recording or a ROS 2 source, which report
// their angles but cannot turn): the page is not offered the pan control, and a request for it
// is refused instead of answered "ok".
class FixedMountCamera final : public Camera {
 public:
  explicit FixedMountCamera(std::unique_ptr<Camera> inner) : inner_(std::move(inner)) {}
  std::optional<Frame> Grab() override { return inner_->Grab(); }
  const CameraInfo& Info() const override { return inner_->Info(); }
  void SetIntegrationTimeRegister(int reg) override { inner_->SetIntegrationTimeRegister(reg); }
  int IntegrationTimeRegister() const override { return inner_->IntegrationTimeRegister(); }
  void SetModulationFrequencyHz(double hz) override { inner_->SetModulationFrequencyHz(hz); }
  void SetDistanceOffsetRegister(int reg) override { inner_->SetDistanceOffsetRegister(reg); }
  int DistanceOffsetRegister() const override { return inner_->DistanceOffsetRegister(); }
  void SetPanAngleRad(double angle_rad) override {
    if (angle_rad != 0.0) throw Error(ErrorCode::kUnsupported, "no pan unit");
  }
  double PanAngleRad() const override { return 0.0; }

 private:
  std::unique_ptr<Camera> inner_;
};

TEST(ViewerServerStandalone, PanIsOfferedOnlyWhereThereIsAPanUnit) {
  ViewerOptions o;
  o.port = 0;
  o.camera_spec = "fixed:hand";
  ViewerServer server(o, PipelineOptions{}, [](const std::string&) {
    return std::make_unique<FixedMountCamera>(OpenSim("sim:hand"));
  });
  server.Start();
  httplib::Client client("127.0.0.1", server.port());
  client.set_read_timeout(5, 0);
  EXPECT_FALSE(json::parse(client.Get("/meta")->body).at("pan_supported").get<bool>());
  const auto r = client.Post("/control", R"({"pan_deg": 30})", "application/json");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 400);
  server.Stop();
}

// A scene change reopens the simulator without the lock; controls another request commits in
// that time must survive it (the scene's request used to write back the state it had copied
// before). The opener blocks until the second request is in, so the order is certain.
TEST(ViewerServerStandalone, ControlsSentDuringASceneChangeAreKept) {
  std::mutex m;
  std::condition_variable cv;
  bool opening = false, release = false;
  int opened = 0;
  ViewerOptions o;
  o.port = 0;
  o.camera_spec = "sim:hand";
  ViewerServer server(o, PipelineOptions{}, [&](const std::string& spec) {
    std::unique_lock<std::mutex> lock(m);
    if (opened++ > 0) {  // not the constructor's open
      opening = true;
      cv.notify_all();
      cv.wait_for(lock, std::chrono::seconds(10), [&] { return release; });
    }
    return OpenSim(spec);
  });
  server.Start();
  std::string scene_reply = "unset";
  std::thread scene(
      [&] { scene_reply = server.ApplyControl(R"({"scene": {"hand_distance_m": 0.5}})"); });
  {
    std::unique_lock<std::mutex> lock(m);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(10), [&] { return opening; }));
  }
  EXPECT_EQ(server.ApplyControl(R"({"filters": {"jump_edge": true}, "paused": true})"), "");
  {
    std::lock_guard<std::mutex> lock(m);
    release = true;
  }
  cv.notify_all();
  scene.join();
  EXPECT_EQ(scene_reply, "");
  httplib::Client client("127.0.0.1", server.port());
  client.set_read_timeout(5, 0);
  const json meta = json::parse(client.Get("/meta")->body);
  EXPECT_TRUE(meta.at("filters").at("jump_edge").get<bool>());
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_TRUE(server.Status().paused);
  server.Stop();
}

// Any 127.x.y.z is loopback: a Host that is neither the bound address nor a loopback name is
// refused there too (DNS rebinding used to pass on 127.0.0.2).
TEST(ViewerServerStandalone, AnotherLoopbackAddressStillChecksTheHost) {
  ViewerOptions o;
  o.port = 0;
  o.bind_address = "127.0.0.2";
  o.camera_spec = "sim:hand";
  ViewerServer server(o, PipelineOptions{}, OpenSim);
  server.Start();
  httplib::Client client("127.0.0.2", server.port());
  client.set_read_timeout(5, 0);
  const std::string port = ":" + std::to_string(server.port());
  const auto foreign = client.Get("/status", {{"Host", "rebind.evil.example" + port}});
  ASSERT_TRUE(foreign);
  EXPECT_EQ(foreign->status, 403);
  const auto own = client.Get("/status", {{"Host", "127.0.0.2" + port}});
  ASSERT_TRUE(own);
  EXPECT_EQ(own->status, 200);
  server.Stop();
}

TEST_F(ViewerServerTest, TheDenoiseAndPredictionTogglesReachTheFrames) {
  // The hand scene, held at one exposure. Denoising makes each usable pixel's ΔL that of the
  // inverse-variance mean of its support: σ / 3 where all nine neighbours of equal σ take
  // part, so the median ΔL of the pixels with one falls well below half (the hand's edges and
  // the image border have smaller supports; 0.6 leaves room for them). The metadata reports it.
  const auto median_delta_l = [&] {
    const std::vector<float> values = NextFrame().Plane<float>("delta_l_m");
    std::vector<float> finite;
    for (const float v : values) {
      if (std::isfinite(v) && v > 0.0f) finite.push_back(v);
    }
    EXPECT_GT(finite.size(), values.size() / 4);
    std::nth_element(finite.begin(), finite.begin() + finite.size() / 2, finite.end());
    return finite.empty() ? 0.0 : double{finite[finite.size() / 2]};
  };
  ASSERT_EQ(Post(R"({"fixed_register": 20})"), 200);
  ASSERT_TRUE(WaitFrames(3));
  const double plain = median_delta_l();
  ASSERT_EQ(Post(R"({"filters": {"denoise": true}})"), 200);
  ASSERT_TRUE(WaitFrames(3));
  const double denoised = median_delta_l();
  EXPECT_GT(plain, 0.0);
  EXPECT_LT(denoised, 0.6 * plain) << plain << " -> " << denoised;
  const auto meta = client_->Get("/meta");
  ASSERT_TRUE(meta && meta->status == 200);
  EXPECT_TRUE(json::parse(meta->body).at("filters").at("denoise").get<bool>());
  // The neighbours' prediction is a stage toggled with the filters too; it excludes the
  // denoising. Kept pixels are delivered combined with what up to 48 neighbours predict, so
  // horizontally adjacent kept distances on the hand and the wall differ far less than two
  // readings do: the median step falls well below half (measured: 10 mm to 0.8 mm; neighbouring
  // predictions share most of their readings).
  EXPECT_FALSE(json::parse(meta->body).at("filters").at("prediction").get<bool>());
  std::string reply;
  ASSERT_EQ(Post(R"({"filters": {"prediction": true}})", &reply), 400) << reply;
  EXPECT_NE(reply.find("exclude each other"), std::string::npos) << reply;
  const auto median_step = [&] {
    const SentFrame frame = NextFrame();
    const std::vector<float> d = frame.Plane<float>("distance_m");
    const std::vector<std::uint16_t> flags = frame.Plane<std::uint16_t>("flags");
    EXPECT_EQ(d.size(), flags.size());
    // Steps between two kept pixels of one surface (not across an edge).
    std::vector<float> steps;
    for (std::size_t i = 0; i + 1 < d.size(); ++i) {
      if (((flags[i] | flags[i + 1]) & kRejectMask) != 0) continue;
      const float step = std::abs(d[i + 1] - d[i]);
      if (std::isfinite(step) && step < 0.2f) steps.push_back(step);
    }
    EXPECT_GT(steps.size(), d.size() / 10);
    std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
    return steps.empty() ? 0.0 : double{steps[steps.size() / 2]};
  };
  ASSERT_EQ(Post(R"({"filters": {"denoise": false}})"), 200);
  ASSERT_TRUE(WaitFrames(3));
  const double raw_step = median_step();
  ASSERT_EQ(Post(R"({"filters": {"prediction": true}})", &reply), 200) << reply;
  ASSERT_TRUE(WaitFrames(3));
  const double combined_step = median_step();
  EXPECT_GT(raw_step, 0.0);
  EXPECT_LT(combined_step, 0.5 * raw_step) << raw_step << " -> " << combined_step;
  const auto after = client_->Get("/meta");
  ASSERT_TRUE(after && after->status == 200);
  const json filters = json::parse(after->body).at("filters");
  EXPECT_TRUE(filters.at("prediction").get<bool>());
  EXPECT_TRUE(filters.at("uncertainty").get<bool>());  // the prediction brings it
}

}  // namespace
}  // namespace tofcam::viewer

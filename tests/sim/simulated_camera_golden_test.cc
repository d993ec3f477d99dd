// Bit-identity of the simulator across refactors: FNV-1a hashes of whole frames (the three
// registers, the ground truth and the frame info) of built-in scenes under several seeds and
// option sets, against golden values recorded with the single-Impl simulator of commit 29661d2
// (before src/sim/ was split into stages, issue 19). A stage split that moves code without
// changing the arithmetic or the order of random draws keeps every hash.
//
// How the golden values were produced: this test was built against 29661d2's simulator with the
// values empty and run once (Release, GCC 12.2, x86-64); each failure message prints the hashes
// the code produced, and those are the values below. Embree's ray-triangle arithmetic differs in
// the last bits between its instruction sets, so there is one set of values per ISA Embree picks,
// told apart by the native packet width: 16 (AVX-512, the machine's own choice), 8 and 4
// (recorded on the same machine with 29661d2's rtcNewDevice config forced to "isa=avx2" and
// "isa=sse4.2"). Another packet width skips the test with a message. They assume the project's
// compiler flags (no -ffast-math, no FMA contraction); the row loops' x86-64-v4, AVX2 and baseline
// clones and the AVX-512 form of the tap noise do the same IEEE operations. A deliberate change of
// the simulator's physics or random stream changes them: then re-record them the same way and say
// why in the commit.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "geometry.h"  // internal: the packet width Embree runs (src/sim)
#include "tofcam/core/pixel_flags.h"
#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::sim {
namespace {

struct Fnv {
  std::uint64_t h = 0xcbf29ce484222325ull;
  void Add(const void* p, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) {
      h ^= b[i];
      h *= 0x100000001b3ull;
    }
  }
  template <typename T>
  void AddImage(const Image<T>& img) {
    Add(img.data(), img.size() * sizeof(T));
  }
  template <typename T>
  void AddValue(T v) {
    Add(&v, sizeof v);
  }
};

std::uint64_t HashFrame(const Frame& f) {
  Fnv h;
  h.AddImage(f.distance);
  h.AddImage(f.amplitude);
  h.AddImage(f.intensity);
  h.AddValue(f.info.sequence);
  h.AddValue(f.info.timestamp_ns);
  h.AddValue(f.info.integration_time_us);
  h.AddValue(f.info.pan_angle_rad);
  if (f.truth) {
    h.AddImage(f.truth->radial_distance_m);
    h.AddImage(f.truth->sigma_m);
    for (std::size_t i = 0; i < f.truth->causes.size(); ++i) {
      h.AddValue(f.truth->causes.data()[i].bits());
    }
  }
  return h.h;
}

struct Case {
  const char* name;
  const char* scene;
  const char* camera;
  void (*setup)(SimulatorOptions&);
  int integration_register;  // 0 = the model's default
  int frames;
  std::vector<std::uint64_t> golden;  // one per frame
  // A truth cause some pixel of some frame must carry (0: none), so that the case provably
  // exercises the path it is named after (saturation, motion, mirrors, ...).
  std::uint16_t must_see = 0;
};

constexpr std::uint16_t Bit(Flag f) { return static_cast<std::uint16_t>(f); }

void Defaults(SimulatorOptions&) {}

std::vector<Case> Cases() {
  return {
      {"wall_seed1",
       "wall",
       "sr2",
       [](SimulatorOptions& o) { o.seed = 1; },
       0,
       3,
       {0xde05df043c95b022ull, 0xe12b5b0c7fad04a3ull, 0xa350943f7b47006cull}},
      {"wall_ideal",
       "wall",
       "sr2",
       [](SimulatorOptions& o) { o = SimulatorOptions::Ideal(); },
       0,
       2,
       {0xce18c1a63f2615b6ull, 0xb2cf833343197eb4ull}},
      {"hand_saturated_bloom",
       "hand",
       "sr2",
       [](SimulatorOptions& o) { o.seed = 11; },
       59,
       2,
       {0xd3e7f58d9bc5d1abull, 0x658e6ef3ec5c4a2dull},
       Bit(Flag::kSaturated)},
      // The same frames on two threads (no golden values of its own: frames must not depend on
      // the thread count; saturation and blooming run on the row pool, 2026-11-27).
      {"hand_saturated_bloom_2threads",
       "hand",
       "sr2",
       [](SimulatorOptions& o) {
         o.seed = 11;
         o.threads = 2;
       },
       59,
       2,
       {0xd3e7f58d9bc5d1abull, 0x658e6ef3ec5c4a2dull},
       Bit(Flag::kSaturated)},
      {"hand_seed7",
       "hand",
       "sr2",
       [](SimulatorOptions& o) { o.seed = 7; },
       0,
       3,
       {0x481ff5116e0d4a4cull, 0x5a618f5e3bfe9a1full, 0x55bd052fe2b4286bull}},
      {"pavilion_2threads",
       "pavilion",
       "sr2",
       [](SimulatorOptions& o) {
         o.seed = 3;
         o.threads = 2;
       },
       0,
       2,
       {0x5515ce0f1476288cull, 0x84378a0073cc6665ull},
       Bit(Flag::kMixed)},
      {"pavilion_ss3",
       "pavilion",
       "sr2",
       [](SimulatorOptions& o) {
         o.seed = 5;
         o.supersampling = 3;
       },
       0,
       1,
       {0xb008626493dfdee2ull}},
      {"mirror",
       "mirror",
       "sr2",
       Defaults,
       0,
       2,
       {0x3c5db35837aac349ull, 0x8151c8931d5518e6ull},
       Bit(Flag::kMultipath)},
      {"lamps",
       "lamps",
       "sr2",
       [](SimulatorOptions& o) { o.seed = 9; },
       0,
       2,
       {0x759fd909226bbecdull, 0x04eac3a43825f9a5ull}},
      {"corridor",
       "corridor",
       "sr3000",
       Defaults,
       0,
       2,
       {0x80dc1547b82c7769ull, 0xcf68e9e5b4a00094ull},
       Bit(Flag::kScattering)},
      {"beyond_range",
       "beyond-range",
       "sr2",
       Defaults,
       0,
       1,
       {0x53246d4e42f8a514ull},
       Bit(Flag::kBeyondUnambiguous)},
      {"demo_moving",
       "demo",
       "sr2",
       [](SimulatorOptions& o) { o.seed = 2; },
       0,
       3,
       {0xb6b2479b9193c1a5ull, 0x874a1b9935b49e9full, 0xc31c9b4902795dcbull},
       0},
      {"box_moving_split_taps",
       "materials: {w: {albedo: 0.6}}\nobjects:\n"
       "  - {type: plane, material: w, size_m: [10, 10], position_m: [0, 0, 4]}\n"
       "  - type: box\n    material: w\n    size_m: [0.4, 0.4, 0.4]\n"
       "    motion: [{t: 0, position_m: [-0.2, 0, 1.5]}, {t: 1, position_m: [9.8, 0, 1.5]}]\n",
       "sr2",
       [](SimulatorOptions& o) { o.seed = 6; },
       60,
       2,
       {0x9a01fa7ae1791a17ull, 0xe027c559aa021094ull},
       Bit(Flag::kMotion)},
      {"approach_moving",
       "approach",
       "sr4000",
       Defaults,
       0,
       3,
       {0xc3d65423801f69f8ull, 0xbd7763eecf89dbdaull, 0x607fce948bae9365ull}},
      {"pavilion_interreflection",
       "pavilion",
       "sr2",
       [](SimulatorOptions& o) {
         o.interreflection = true;
         o.threads = 2;
       },
       0,
       1,
       {0xc51972cb4fffbdf7ull},
       Bit(Flag::kMultipath)},
      {"demo_640x480_2threads",
       "demo",
       "generic640x480",
       [](SimulatorOptions& o) {
         o.seed = 4;
         o.threads = 2;
       },
       0,
       2,
       {0x316bf8e7f658183eull, 0x747d11e280ea7c14ull},
       Bit(Flag::kMixed)},
      {"wall_ss1",
       "wall",
       "sr2",
       [](SimulatorOptions& o) { o.supersampling = 1; },
       0,
       1,
       {0x9e562f19039dd492ull}},
  };
}

// Golden values of the other Embree ISAs (see the header), by case name: packet width 8, 4.
struct IsaGolden {
  const char* name;
  std::vector<std::uint64_t> width8, width4;
};

std::vector<IsaGolden> OtherIsas() {
  return {
      {"wall_seed1",
       {0xfa7045e2fb2b4674ull, 0x4fd5d4cde604b93eull, 0xd39aaff6444f71efull},
       {0xceb6c02c7f5bf83full, 0x837fd804f594aa28ull, 0xf026bc2a1851148aull}},
      {"wall_ideal",
       {0xec83efeb78c580eaull, 0x7d7d9869e1f395d4ull},
       {0x779f64452be5fb0bull, 0xbf0e13a3cea266d9ull}},
      {"hand_saturated_bloom",
       {0x5e9925f62c3c1623ull, 0x933df3ffd01a348full},
       {0xbad2e35186305a5aull, 0xa9ae12cf1b31dd88ull}},
      {"hand_saturated_bloom_2threads",
       {0x5e9925f62c3c1623ull, 0x933df3ffd01a348full},
       {0xbad2e35186305a5aull, 0xa9ae12cf1b31dd88ull}},
      {"hand_seed7",
       {0x011b9dd8c1aa00a8ull, 0xe3ecbdc3d16dda17ull, 0x78218cd0a00a4306ull},
       {0x4831ef28440c92adull, 0x29933a7e177d67a4ull, 0x58662579b5350230ull}},
      {"pavilion_2threads",
       {0x4c596b3b0f1ae739ull, 0xc98256b22e15afcdull},
       {0xa1ba3ecdb8b81245ull, 0xcb2954d3e91118edull}},
      {"pavilion_ss3", {0xfa93b9fc8a3275f3ull}, {0xcf37e75aeec55b29ull}},
      {"mirror",
       {0x45a31aa5e6e10ebbull, 0x576aef2b3ebb19b5ull},
       {0x43aa6e673ac35be1ull, 0x6ba78d54e838e832ull}},
      {"lamps",
       {0xe8a543b9f50da024ull, 0xcceaed8b6294fce8ull},
       {0x998a48a03cd27048ull, 0x227c0c87e5f2501dull}},
      {"corridor",
       {0xb908414f7643f91bull, 0xf2c9723b4aacfc9full},
       {0xdda739bf0b3e047dull, 0x3c397d7beb1671a3ull}},
      {"beyond_range", {0xe279b35c5a94ff56ull}, {0x04b57928dd677376ull}},
      {"demo_moving",
       {0x07b2df69dca0bbc0ull, 0x0db3d215a78962ceull, 0xfd7b04f1c135ebc9ull},
       {0x5bba7e4a2b134ea7ull, 0x4e9c9d23d185a418ull, 0x347034431feffdb9ull}},
      {"box_moving_split_taps",
       {0xce051e74235248dcull, 0xe3b884c8ef9eaf4bull},
       {0xb5df134366f09aeeull, 0x6f242acb4b877e0full}},
      {"approach_moving",
       {0x7ea0428d35b1e0f5ull, 0x626a34dc4b15f111ull, 0xecaa6ec82f0edd4full},
       {0xff4720a0ce919c7bull, 0x2ac81d1aba614eaeull, 0xee5bc75ced0a3d58ull}},
      {"pavilion_interreflection", {0x3acbdc68c61e5265ull}, {0x76a42407db1a36ffull}},
      {"demo_640x480_2threads",
       {0xfebccf8cd16f17e7ull, 0xdb3459ed2d520b7full},
       {0xce77ca716e0ad93eull, 0x2f1aeb3ae4fcc5dfull}},
      {"wall_ss1", {0xf8f1395cc0f492edull}, {0x9997ee4ee83e8460ull}},
  };
}

// Rays per packet of the Embree ISA this CPU runs (16, 8, 4 or 1).
int NativePacketWidth() {
  const Scene scene = ParseScene(
      "materials: {w: {albedo: 0.5}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [1, 1], position_m: [0, 0, 1]}\n",
      "inline", {});
  return internal::SceneGeometry(scene).PacketWidth();
}

class GoldenTest : public ::testing::TestWithParam<int> {};

TEST_P(GoldenTest, FramesMatchThePreRefactorSimulator) {
  const Case c = Cases()[static_cast<std::size_t>(GetParam())];
  SimulatorOptions opt;
  c.setup(opt);
  opt.integration_time_register = c.integration_register;
  const std::string spec = c.scene;
  Scene scene;
  if (spec.rfind("materials:", 0) == 0) {
    scene = ParseScene(spec, "inline", {});
  } else {
    const auto [name, overrides] = ParseSceneSpec(spec);
    scene = LoadBuiltinScene(name, overrides);
  }
  SimulatedCamera cam(std::move(scene), ResolveCameraModel(c.camera), opt);
  std::string got;
  std::uint16_t seen = 0;
  for (int f = 0; f < c.frames; ++f) {
    const Frame frame = *cam.Grab();
    ASSERT_TRUE(frame.truth.has_value());
    for (std::size_t i = 0; i < frame.truth->causes.size(); ++i) {
      seen |= frame.truth->causes.data()[i].bits();
    }
    char buf[32];
    std::snprintf(buf, sizeof buf, "0x%016llxull, ",
                  static_cast<unsigned long long>(HashFrame(frame)));
    got += buf;
  }
  const int width = NativePacketWidth();
  const std::vector<std::uint64_t>* golden = width == 16 ? &c.golden : nullptr;
  const std::vector<IsaGolden> isas = OtherIsas();
  for (const IsaGolden& g : isas) {
    if (std::string(g.name) == c.name && width != 16) {
      golden = width == 8 ? &g.width8 : width == 4 ? &g.width4 : nullptr;
    }
  }
  if (golden == nullptr) GTEST_SKIP() << "no golden values for Embree packet width " << width;
  std::string want;
  for (std::uint64_t g : *golden) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "0x%016llxull, ", static_cast<unsigned long long>(g));
    want += buf;
  }
  EXPECT_EQ(got, want) << c.name;
  EXPECT_EQ(seen & c.must_see, c.must_see) << c.name << ": the case does not exercise its path";
}

INSTANTIATE_TEST_SUITE_P(Scenes, GoldenTest, ::testing::Range(0, static_cast<int>(Cases().size())),
                         [](const ::testing::TestParamInfo<int>& p) {
                           return std::string(Cases()[static_cast<std::size_t>(p.param)].name);
                         });

}  // namespace
}  // namespace tofcam::sim

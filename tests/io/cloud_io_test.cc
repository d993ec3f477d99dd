#include "tofcam/io/cloud_io.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "../scratch_dir.h"
#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

namespace fs = std::filesystem;
constexpr float kNan = std::numeric_limits<float>::quiet_NaN();

fs::path Temp(const std::string& name) { return testing::ScratchDir("tofcam_cloud_io_") / name; }

// What an independent reader recovers: named columns as doubles, plus header facts.
struct Parsed {
  std::vector<std::string> names;
  std::map<std::string, std::vector<double>> columns;
  std::size_t count = 0;
  std::map<std::string, std::string> header;  // PCD keys / PLY "format" and comments
};

// A small PLY reader written from the PLY specification (not from the writer): header lines up
// to end_header, one element "vertex" with scalar properties of any listed type, then ASCII or
// binary little-endian rows.
Parsed ReadPly(const fs::path& path) {
  const std::string bytes = ReadFile(path);
  Parsed p;
  std::size_t pos = 0;
  std::vector<std::string> types;
  bool ascii = false;
  for (;;) {
    const std::size_t eol = bytes.find('\n', pos);
    if (eol == std::string::npos) throw std::runtime_error("PLY: no end_header");
    const std::string line = bytes.substr(pos, eol - pos);
    pos = eol + 1;
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "end_header") break;
    if (key == "format") {
      std::string f;
      ls >> f;
      p.header["format"] = f;
      ascii = f == "ascii";
    } else if (key == "element") {
      std::string name;
      ls >> name >> p.count;
      if (name != "vertex") throw std::runtime_error("PLY: unexpected element");
    } else if (key == "property") {
      std::string type, name;
      ls >> type >> name;
      types.push_back(type);
      p.names.push_back(name);
    } else if (key == "comment") {
      p.header["comment"] += line.substr(8) + "\n";
    }
  }
  auto size_of = [](const std::string& t) -> std::size_t {
    if (t == "float" || t == "float32" || t == "int" || t == "uint") return 4;
    if (t == "ushort" || t == "uint16" || t == "short") return 2;
    if (t == "uchar" || t == "char") return 1;
    if (t == "double") return 8;
    throw std::runtime_error("PLY: unknown type " + t);
  };
  if (ascii) {
    std::istringstream body(bytes.substr(pos));
    for (std::size_t i = 0; i < p.count; ++i) {
      for (const std::string& n : p.names) {
        std::string tok;
        body >> tok;
        p.columns[n].push_back(std::strtod(tok.c_str(), nullptr));  // strtod accepts "nan"
      }
    }
    return p;
  }
  std::size_t row = 0;
  for (const std::string& t : types) row += size_of(t);
  if (bytes.size() - pos != row * p.count) throw std::runtime_error("PLY: wrong body size");
  for (std::size_t i = 0; i < p.count; ++i) {
    for (std::size_t k = 0; k < types.size(); ++k) {
      const unsigned char* b = reinterpret_cast<const unsigned char*>(bytes.data() + pos);
      double v = 0;
      if (types[k] == "float") {
        // Assemble the little-endian bytes explicitly.
        const std::uint32_t u = b[0] | (b[1] << 8) | (b[2] << 16) | (std::uint32_t{b[3]} << 24);
        float f;
        std::memcpy(&f, &u, 4);
        v = f;
      } else if (types[k] == "ushort") {
        v = b[0] | (b[1] << 8);
      } else {
        throw std::runtime_error("PLY: type not expected here: " + types[k]);
      }
      p.columns[p.names[k]].push_back(v);
      pos += size_of(types[k]);
    }
  }
  return p;
}

// A PCD v0.7 reader from the PCL documentation: header keys, then DATA binary with fields packed
// in FIELDS order with the listed SIZE / TYPE.
Parsed ReadPcd(const fs::path& path) {
  const std::string bytes = ReadFile(path);
  Parsed p;
  std::size_t pos = 0;
  for (;;) {
    const std::size_t eol = bytes.find('\n', pos);
    if (eol == std::string::npos) throw std::runtime_error("PCD: no DATA line");
    const std::string line = bytes.substr(pos, eol - pos);
    pos = eol + 1;
    if (line.empty() || line[0] == '#') continue;
    const std::size_t sp = line.find(' ');
    p.header[line.substr(0, sp)] = line.substr(sp + 1);
    if (line.rfind("DATA", 0) == 0) break;
  }
  std::istringstream fields(p.header["FIELDS"]), sizes(p.header["SIZE"]), tps(p.header["TYPE"]);
  std::vector<int> size;
  std::vector<std::string> type;
  for (std::string n; fields >> n;) p.names.push_back(n);
  for (int s; sizes >> s;) size.push_back(s);
  for (std::string t; tps >> t;) type.push_back(t);
  p.count = std::stoul(p.header["POINTS"]);
  for (std::size_t i = 0; i < p.count; ++i) {
    for (std::size_t k = 0; k < p.names.size(); ++k) {
      double v = 0;
      if (type[k] == "F" && size[k] == 4) {
        float f;
        std::memcpy(&f, bytes.data() + pos, 4);
        v = f;
      } else if (type[k] == "U" && size[k] == 2) {
        std::uint16_t u;
        std::memcpy(&u, bytes.data() + pos, 2);
        v = u;
      } else {
        throw std::runtime_error("PCD: unexpected field type");
      }
      p.columns[p.names[k]].push_back(v);
      pos += static_cast<std::size_t>(size[k]);
    }
  }
  if (pos != bytes.size()) throw std::runtime_error("PCD: trailing bytes");
  return p;
}

// 3 x 2 cloud: point 1 rejected (NaN coordinates), point 4 valid but with a truth bit.
PointCloud Sample() {
  PointCloud c;
  c.Resize(3, 2);
  for (std::size_t i = 0; i < 6; ++i) {
    c.x[i] = 0.1f * static_cast<float>(i) - 0.25f;
    c.y[i] = -0.3f + 1e-7f * static_cast<float>(i);
    c.z[i] = 1.0f + 0.123456789f * static_cast<float>(i);
    c.amplitude[i] = 1000.0f + static_cast<float>(i);
    c.intensity[i] = 20000.5f;
    c.delta_l_m[i] = 0.0125f * static_cast<float>(i);
  }
  c.x[1] = c.y[1] = c.z[1] = kNan;
  c.flags[1] = Flag::kHighDeltaL;
  c.flags[4] = Flag::kMixed;
  c.intensity[5] = kNan;
  return c;
}

void ExpectSame(double got, float want, const std::string& what) {
  if (std::isnan(want)) {
    EXPECT_TRUE(std::isnan(got)) << what;
  } else {
    EXPECT_EQ(static_cast<float>(got), want) << what;  // float round trip is exact
  }
}

void ExpectColumns(const Parsed& p, const PointCloud& c, const std::vector<std::size_t>& idx) {
  ASSERT_EQ(p.count, idx.size());
  const std::vector<std::string> want = {"x",         "y",       "z",    "amplitude",
                                         "intensity", "delta_l", "flags"};
  ASSERT_EQ(p.names, want);
  for (std::size_t k = 0; k < idx.size(); ++k) {
    const std::size_t i = idx[k];
    const std::string at = " at point " + std::to_string(i);
    ExpectSame(p.columns.at("x")[k], c.x[i], "x" + at);
    ExpectSame(p.columns.at("y")[k], c.y[i], "y" + at);
    ExpectSame(p.columns.at("z")[k], c.z[i], "z" + at);
    ExpectSame(p.columns.at("amplitude")[k], c.amplitude[i], "amplitude" + at);
    ExpectSame(p.columns.at("intensity")[k], c.intensity[i], "intensity" + at);
    ExpectSame(p.columns.at("delta_l")[k], c.delta_l_m[i], "delta_l" + at);
    EXPECT_EQ(p.columns.at("flags")[k], c.flags[i].bits()) << at;
  }
}

TEST(CloudIoTest, BinaryPlyRoundTripsEveryPoint) {
  const PointCloud c = Sample();
  const fs::path path = Temp("all.ply");
  WritePly(path, c, PlyFormat::kBinary, false);
  const Parsed p = ReadPly(path);
  EXPECT_EQ(p.header.at("format"), "binary_little_endian");
  EXPECT_NE(p.header.at("comment").find("organized 3 2"), std::string::npos);
  ExpectColumns(p, c, {0, 1, 2, 3, 4, 5});
}

TEST(CloudIoTest, AsciiPlyOnlyValidDropsRejectedPoints) {
  const PointCloud c = Sample();
  const fs::path path = Temp("valid.ply");
  WritePly(path, c, PlyFormat::kAscii, true);
  const Parsed p = ReadPly(path);
  EXPECT_EQ(p.header.at("format"), "ascii");
  ExpectColumns(p, c, {0, 2, 3, 4, 5});  // point 1 is rejected; point 4's truth bit is kept
  WritePly(path, c, PlyFormat::kAscii, false);
  ExpectColumns(ReadPly(path), c, {0, 1, 2, 3, 4, 5});  // "nan" parses back as NaN
}

TEST(CloudIoTest, PcdIsOrganisedUnlessOnlyValid) {
  const PointCloud c = Sample();
  const fs::path path = Temp("cloud.pcd");
  WritePcd(path, c, false);
  Parsed p = ReadPcd(path);
  EXPECT_EQ(p.header.at("VERSION"), "0.7");
  EXPECT_EQ(p.header.at("WIDTH"), "3");
  EXPECT_EQ(p.header.at("HEIGHT"), "2");
  EXPECT_EQ(p.header.at("DATA"), "binary");
  EXPECT_EQ(p.header.at("COUNT"), "1 1 1 1 1 1 1");
  ExpectColumns(p, c, {0, 1, 2, 3, 4, 5});
  WritePcd(path, c, true);
  p = ReadPcd(path);
  EXPECT_EQ(p.header.at("WIDTH"), "5");
  EXPECT_EQ(p.header.at("HEIGHT"), "1");
  ExpectColumns(p, c, {0, 2, 3, 4, 5});
}

TEST(CloudIoTest, EmptyCloudWritesValidFiles) {
  PointCloud c;
  const fs::path ply = Temp("empty.ply"), pcd = Temp("empty.pcd");
  WritePly(ply, c);
  WritePcd(pcd, c);
  EXPECT_EQ(ReadPly(ply).count, 0u);
  EXPECT_EQ(ReadPcd(pcd).count, 0u);
}

TEST(CloudIoTest, ErrorsAreReported) {
  const PointCloud c = Sample();
  const fs::path bad = Temp("no_such_dir") / "x.ply";
  try {
    WritePly(bad, c);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kIo);
    EXPECT_NE(std::string(e.what()).find("x.ply"), std::string::npos);
  }
  EXPECT_THROW(WritePcd(Temp("no_such_dir") / "x.pcd", c), Error);
  PointCloud broken = Sample();
  broken.delta_l_m.pop_back();
  try {
    WritePcd(Temp("broken.pcd"), broken);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
  }
  EXPECT_FALSE(fs::exists(Temp("broken.pcd")));
  // A failed write leaves the previous file untouched (atomic write).
  const fs::path keep = Temp("keep.ply");
  WritePly(keep, c);
  const std::string before = ReadFile(keep);
  EXPECT_THROW(WritePly(keep, broken), Error);
  EXPECT_EQ(ReadFile(keep), before);
}

}  // namespace
}  // namespace tofcam

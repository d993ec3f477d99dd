#include "tofcam/io/cloud_io.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

static_assert(std::endian::native == std::endian::little,
              "the PLY/PCD writers emit little-endian data by copying native floats");

std::vector<std::size_t> Selected(const PointCloud& cloud, bool only_valid) {
  std::vector<std::size_t> idx;
  idx.reserve(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (!only_valid || cloud.IsValid(i)) idx.push_back(i);
  }
  return idx;
}

// One point as packed little-endian bytes: 6 floats and a ushort (26 bytes).
constexpr std::size_t kPointBytes = 6 * sizeof(float) + sizeof(std::uint16_t);

void PackPoint(const PointCloud& c, std::size_t i, char* out) {
  const float v[6] = {c.x[i], c.y[i], c.z[i], c.amplitude[i], c.intensity[i], c.delta_l_m[i]};
  std::memcpy(out, v, sizeof v);
  const std::uint16_t f = c.flags[i].bits();
  std::memcpy(out + sizeof v, &f, sizeof f);
}

void AppendFloat(std::string& s, float v) {
  char buf[32];
  if (std::isnan(v)) {
    s += "nan";
  } else if (std::isinf(v)) {
    s += v > 0 ? "inf" : "-inf";
  } else {
    const int n = std::snprintf(buf, sizeof buf, "%.9g", static_cast<double>(v));
    s.append(buf, static_cast<std::size_t>(n));
  }
}

}  // namespace

void WritePly(const std::filesystem::path& path, const PointCloud& cloud, PlyFormat format,
              bool only_valid) {
  cloud.Validate();
  const std::vector<std::size_t> idx = Selected(cloud, only_valid);
  std::string out;
  out += "ply\n";
  out += format == PlyFormat::kBinary ? "format binary_little_endian 1.0\n" : "format ascii 1.0\n";
  out +=
      "comment tofcam point cloud: x y z in m, amplitude and intensity in register units, "
      "delta_l in m, flags = tofcam PixelFlags bits\n";
  if (!only_valid) {
    out += "comment organized " + std::to_string(cloud.width) + " " + std::to_string(cloud.height) +
           "\n";
  }
  out += "element vertex " + std::to_string(idx.size()) + "\n";
  for (const char* name : {"x", "y", "z", "amplitude", "intensity", "delta_l"}) {
    out += std::string("property float ") + name + "\n";
  }
  out += "property ushort flags\nend_header\n";
  if (format == PlyFormat::kBinary) {
    const std::size_t header = out.size();
    out.resize(header + idx.size() * kPointBytes);
    char* p = out.data() + header;
    for (std::size_t i : idx) {
      PackPoint(cloud, i, p);
      p += kPointBytes;
    }
  } else {
    out.reserve(out.size() + idx.size() * 80);
    for (std::size_t i : idx) {
      for (float v : {cloud.x[i], cloud.y[i], cloud.z[i], cloud.amplitude[i], cloud.intensity[i],
                      cloud.delta_l_m[i]}) {
        AppendFloat(out, v);
        out += ' ';
      }
      out += std::to_string(cloud.flags[i].bits());
      out += '\n';
    }
  }
  WriteFileAtomically(path, out);
}

void WritePcd(const std::filesystem::path& path, const PointCloud& cloud, bool only_valid) {
  cloud.Validate();
  const std::vector<std::size_t> idx = Selected(cloud, only_valid);
  const std::size_t width = only_valid ? idx.size() : static_cast<std::size_t>(cloud.width);
  const std::size_t height = only_valid ? 1 : static_cast<std::size_t>(cloud.height);
  std::string out;
  out += "# .PCD v0.7 - Point Cloud Data file format\n";
  out += "VERSION 0.7\n";
  out += "FIELDS x y z amplitude intensity delta_l flags\n";
  out += "SIZE 4 4 4 4 4 4 2\n";
  out += "TYPE F F F F F F U\n";
  out += "COUNT 1 1 1 1 1 1 1\n";
  out += "WIDTH " + std::to_string(width) + "\n";
  out += "HEIGHT " + std::to_string(height) + "\n";
  out += "VIEWPOINT 0 0 0 1 0 0 0\n";
  out += "POINTS " + std::to_string(idx.size()) + "\n";
  out += "DATA binary\n";
  const std::size_t header = out.size();
  out.resize(header + idx.size() * kPointBytes);
  char* p = out.data() + header;
  for (std::size_t i : idx) {
    PackPoint(cloud, i, p);
    p += kPointBytes;
  }
  WriteFileAtomically(path, out);
}

}  // namespace tofcam

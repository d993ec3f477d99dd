#include "tofcam/sim/scene.h"

#include <tiny_obj_loader.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <utility>
#include <vector>

#include "tofcam/core/atomic_file.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "yaml_util.h"

namespace tofcam::sim {
namespace {

// Object sizes (plane and box sides, radii, heights), m: smaller vanishes between the rays,
// larger leaves float precision at the scene's scale.
constexpr double kMinSizeM = 1e-6;
constexpr double kMaxSizeM = 1e4;

using internal::YamlReader;

constexpr double kDegToRad = kPi / 180.0;

Eigen::Matrix3d EulerDeg(const Eigen::Vector3d& deg) {
  return (Eigen::AngleAxisd(deg.z() * kDegToRad, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(deg.y() * kDegToRad, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(deg.x() * kDegToRad, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

using Verts = std::vector<Eigen::Vector3f>;
using Tris = std::vector<Eigen::Vector3i>;

void AddQuad(Verts& v, Tris& t, const Eigen::Vector3f& a, const Eigen::Vector3f& b,
             const Eigen::Vector3f& c, const Eigen::Vector3f& d) {
  const int i = static_cast<int>(v.size());
  v.insert(v.end(), {a, b, c, d});
  t.emplace_back(i, i + 1, i + 2);
  t.emplace_back(i, i + 2, i + 3);
}

void MakePlane(const Eigen::Vector2d& size, Verts& v, Tris& t) {
  const float hx = static_cast<float>(size.x() / 2), hy = static_cast<float>(size.y() / 2);
  AddQuad(v, t, {-hx, -hy, 0}, {hx, -hy, 0}, {hx, hy, 0}, {-hx, hy, 0});
}

void MakeBox(const Eigen::Vector3d& size, Verts& v, Tris& t) {
  const Eigen::Vector3f h = (size / 2).cast<float>();
  const float x = h.x(), y = h.y(), z = h.z();
  AddQuad(v, t, {-x, -y, -z}, {x, -y, -z}, {x, y, -z}, {-x, y, -z});
  AddQuad(v, t, {-x, -y, z}, {-x, y, z}, {x, y, z}, {x, -y, z});
  AddQuad(v, t, {-x, -y, -z}, {-x, y, -z}, {-x, y, z}, {-x, -y, z});
  AddQuad(v, t, {x, -y, -z}, {x, -y, z}, {x, y, z}, {x, y, -z});
  AddQuad(v, t, {-x, -y, -z}, {-x, -y, z}, {x, -y, z}, {x, -y, -z});
  AddQuad(v, t, {-x, y, -z}, {x, y, -z}, {x, y, z}, {-x, y, z});
}

void MakeSphere(double radius, Verts& v, Tris& t) {
  constexpr int kLat = 16, kLon = 32;
  const int base = static_cast<int>(v.size());
  for (int i = 0; i <= kLat; ++i) {
    const double th = kPi * i / kLat;
    for (int j = 0; j < kLon; ++j) {
      const double ph = 2 * kPi * j / kLon;
      v.emplace_back(static_cast<float>(radius * std::sin(th) * std::cos(ph)),
                     static_cast<float>(radius * std::cos(th)),
                     static_cast<float>(radius * std::sin(th) * std::sin(ph)));
    }
  }
  for (int i = 0; i < kLat; ++i) {
    for (int j = 0; j < kLon; ++j) {
      const int a = base + i * kLon + j, b = base + i * kLon + (j + 1) % kLon;
      const int c = a + kLon, d = b + kLon;
      t.emplace_back(a, c, b);
      t.emplace_back(b, c, d);
    }
  }
}

void MakeCylinder(double radius, double height, Verts& v, Tris& t) {
  constexpr int kSeg = 32;
  const int base = static_cast<int>(v.size());
  const float h = static_cast<float>(height / 2);
  for (int j = 0; j < kSeg; ++j) {
    const double ph = 2 * kPi * j / kSeg;
    const float x = static_cast<float>(radius * std::cos(ph)),
                z = static_cast<float>(radius * std::sin(ph));
    v.emplace_back(x, -h, z);
    v.emplace_back(x, h, z);
  }
  const int top = static_cast<int>(v.size());
  v.emplace_back(0.f, -h, 0.f);
  v.emplace_back(0.f, h, 0.f);
  for (int j = 0; j < kSeg; ++j) {
    const int a = base + 2 * j, b = base + 2 * ((j + 1) % kSeg);
    t.emplace_back(a, a + 1, b + 1);
    t.emplace_back(a, b + 1, b);
    t.emplace_back(top, a, b);
    t.emplace_back(top + 1, b + 1, a + 1);
  }
}

// ---- PLY ----

[[noreturn]] void PlyFail(const std::filesystem::path& path, const std::string& problem) {
  throw Error(ErrorCode::kFormat, path.string() + ": PLY: " + problem);
}

int PlyTypeSize(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "int32" || type == "uint32" || type == "float" ||
      type == "float32")
    return 4;
  if (type == "double" || type == "float64") return 8;
  return 0;
}

double PlyReadBinary(const char*& p, const char* end, const std::string& type,
                     const std::filesystem::path& path) {
  const int n = PlyTypeSize(type);
  if (end - p < n) PlyFail(path, "truncated binary data");
  double v = 0;
  auto rd = [&](auto tag) {
    decltype(tag) x;
    std::memcpy(&x, p, sizeof x);
    v = static_cast<double>(x);
  };
  if (type == "char" || type == "int8")
    rd(std::int8_t{});
  else if (type == "uchar" || type == "uint8")
    rd(std::uint8_t{});
  else if (type == "short" || type == "int16")
    rd(std::int16_t{});
  else if (type == "ushort" || type == "uint16")
    rd(std::uint16_t{});
  else if (type == "int" || type == "int32")
    rd(std::int32_t{});
  else if (type == "uint" || type == "uint32")
    rd(std::uint32_t{});
  else if (type == "float" || type == "float32")
    rd(float{});
  else
    rd(double{});
  p += n;
  return v;
}

struct PlyProperty {
  std::string name, type, count_type;  // count_type non-empty for lists
};
struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> props;
};

void LoadPly(const std::filesystem::path& path, Verts& verts, Tris& tris) {
  const std::string data = ReadFile(path, std::size_t{1} << 30);
  std::size_t pos = 0;
  auto next_line = [&]() -> std::string {
    const std::size_t e = data.find('\n', pos);
    if (e == std::string::npos) PlyFail(path, "header has no end_header");
    std::string line = data.substr(pos, e - pos);
    pos = e + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return line;
  };
  if (next_line() != "ply") PlyFail(path, "missing 'ply' magic");
  std::string format;
  std::vector<PlyElement> elements;
  for (;;) {
    const std::string line = next_line();
    std::istringstream in(line);
    std::string word;
    in >> word;
    if (word == "end_header") break;
    if (word == "comment" || word == "obj_info" || word.empty()) continue;
    if (word == "format") {
      std::string version;
      in >> format >> version;
      if (format != "ascii" && format != "binary_little_endian") {
        PlyFail(path, "unsupported format '" + format + "' (ascii or binary_little_endian)");
      }
    } else if (word == "element") {
      PlyElement e;
      in >> e.name >> e.count;
      if (!in || e.count < 0 || e.count > (1LL << 26))
        PlyFail(path, "bad element line '" + line + "'");
      elements.push_back(e);
    } else if (word == "property") {
      if (elements.empty()) PlyFail(path, "property before element");
      PlyProperty p;
      in >> p.type;
      if (p.type == "list") {
        in >> p.count_type >> p.type;
        if (PlyTypeSize(p.count_type) == 0) PlyFail(path, "bad list count type in '" + line + "'");
      }
      in >> p.name;
      if (!in || PlyTypeSize(p.type) == 0) PlyFail(path, "bad property line '" + line + "'");
      elements.back().props.push_back(p);
    } else {
      PlyFail(path, "unknown header line '" + line + "'");
    }
  }
  if (format.empty()) PlyFail(path, "missing format line");
  const bool ascii = format == "ascii";
  const char* p = data.data() + pos;
  const char* end = data.data() + data.size();
  std::istringstream text(ascii ? data.substr(pos) : std::string());
  auto read_value = [&](const std::string& type) -> double {
    if (!ascii) return PlyReadBinary(p, end, type, path);
    double v;
    if (!(text >> v)) PlyFail(path, "truncated or non-numeric ASCII data");
    return v;
  };
  long long vertex_base = static_cast<long long>(verts.size());
  long long vertex_count = 0;
  bool have_vertices = false;
  for (const PlyElement& e : elements) {
    const bool is_vertex = e.name == "vertex";
    const bool is_face = e.name == "face";
    int ix = -1, iy = -1, iz = -1, iface = -1;
    for (int i = 0; i < static_cast<int>(e.props.size()); ++i) {
      const auto& pr = e.props[i];
      if (pr.name == "x") ix = i;
      if (pr.name == "y") iy = i;
      if (pr.name == "z") iz = i;
      if (pr.name == "vertex_indices" || pr.name == "vertex_index") iface = i;
    }
    if (is_vertex && (ix < 0 || iy < 0 || iz < 0)) PlyFail(path, "vertex element lacks x, y, z");
    if (is_face && iface < 0) PlyFail(path, "face element lacks vertex_indices");
    if (is_face && !have_vertices) PlyFail(path, "face element before vertex element");
    std::vector<double> vals(e.props.size());
    std::vector<long long> poly;
    for (long long n = 0; n < e.count; ++n) {
      for (int i = 0; i < static_cast<int>(e.props.size()); ++i) {
        const auto& pr = e.props[i];
        if (pr.count_type.empty()) {
          vals[i] = read_value(pr.type);
        } else {
          const double cnt = read_value(pr.count_type);
          if (cnt < 0 || cnt > 1000 || cnt != std::floor(cnt)) PlyFail(path, "bad list length");
          poly.clear();
          for (int k = 0; k < static_cast<int>(cnt); ++k) {
            const double idx = read_value(pr.type);
            if (i == iface) {
              if (idx < 0 || idx >= static_cast<double>(vertex_count) || idx != std::floor(idx)) {
                PlyFail(path, "face " + std::to_string(n) + " has vertex index out of range");
              }
              poly.push_back(static_cast<long long>(idx));
            }
          }
          if (i == iface) {
            if (poly.size() < 3) PlyFail(path, "face " + std::to_string(n) + " has < 3 vertices");
            for (std::size_t k = 1; k + 1 < poly.size(); ++k) {
              tris.emplace_back(static_cast<int>(vertex_base + poly[0]),
                                static_cast<int>(vertex_base + poly[k]),
                                static_cast<int>(vertex_base + poly[k + 1]));
            }
          }
        }
      }
      if (is_vertex) {
        // Checked as floats: a double beyond the float range (1e39) is finite but no vertex
        // (and converting it is undefined behaviour).
        const auto in_float = [](double x) {
          return std::isfinite(x) && std::abs(x) <= std::numeric_limits<float>::max();
        };
        if (!in_float(vals[ix]) || !in_float(vals[iy]) || !in_float(vals[iz])) {
          PlyFail(path, "vertex " + std::to_string(n) + " is not a finite float");
        }
        verts.emplace_back(static_cast<float>(vals[ix]), static_cast<float>(vals[iy]),
                           static_cast<float>(vals[iz]));
      }
    }
    if (is_vertex) {
      vertex_count = e.count;
      have_vertices = true;
    }
  }
  if (!have_vertices) PlyFail(path, "no vertex element");
}

// tinyobjloader reads what it cannot parse as 0 ("v abc 1 2", "v nan 1 2", "v 0x1p3 1 2"),
// accepts a vertex with two coordinates and wraps a face index beyond int
// ("f 1 2 99999999999999999999") into range, so a malformed mesh would render as a different
// one. The vertex and face lines are checked here first: a vertex is 3 (or 4 with w, or 6 with a
// colour) decimal numbers within the float range (tiny ones that round to 0 included), a face at
// least 3 vertex references whose index (before any '/') is a whole number naming a vertex: 1 to
// the file's vertex count, or counted back from the last vertex so far when negative (OBJ's
// relative indices). Line ends may be LF, CRLF or CR; '#' starts a comment.
bool ObjNumberOk(const std::string& t) {
  double x = 0.0;
  const char* begin = t.data() + (t.size() > 1 && t[0] == '+' && t[1] != '-' ? 1 : 0);
  const char* end = t.data() + t.size();
  const auto [ptr, ec] = std::from_chars(begin, end, x);  // decimal only, no locale
  if (ptr != end) return false;
  if (ec == std::errc::result_out_of_range) {
    // Underflow (1e-320) is a number that rounds to 0; overflow is not one.
    const auto e = t.find_first_of("eE");
    return e != std::string::npos && e + 1 < t.size() && t[e + 1] == '-';
  }
  return ec == std::errc() && std::isfinite(x) && std::abs(x) <= std::numeric_limits<float>::max();
}

void CheckObjText(const std::filesystem::path& path, std::string text) {
  const auto fail = [&](std::size_t line, const std::string& problem) {
    throw Error(ErrorCode::kFormat,
                path.string() + ":" + std::to_string(line) + ": OBJ: " + problem);
  };
  // CRLF to LF, then a lone CR (old Mac files) to LF: the line numbers stay those of the file.
  std::string unified;
  unified.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] != '\r') {
      unified += text[i];
    } else if (i + 1 >= text.size() || text[i + 1] != '\n') {
      unified += '\n';
    }
  }
  text.swap(unified);
  // Each line's kind and tokens, comments dropped; then the file's vertex count.
  const auto tokens_of = [](const std::string& line) {
    std::istringstream in(line.substr(0, line.find('#')));
    std::vector<std::string> tokens;
    for (std::string t; in >> t;) tokens.push_back(t);
    return tokens;
  };
  long long total = 0;
  {
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);) {
      const auto tokens = tokens_of(line);
      total += !tokens.empty() && tokens[0] == "v";
    }
  }
  long long vertices = 0;  // defined so far
  std::istringstream lines(text);
  std::string line;
  for (std::size_t number = 1; std::getline(lines, line); ++number) {
    const std::vector<std::string> tokens = tokens_of(line);
    if (tokens.empty() || (tokens[0] != "v" && tokens[0] != "f")) continue;
    const std::size_t n = tokens.size() - 1;
    if (tokens[0] == "v") {
      if (n != 3 && n != 4 && n != 6) {
        fail(number, "a vertex needs 3 coordinates, got " + std::to_string(n) + " numbers");
      }
      for (std::size_t k = 1; k <= n; ++k) {
        if (!ObjNumberOk(tokens[k])) {
          fail(number, "vertex coordinate '" + tokens[k] + "' is not a finite decimal number");
        }
      }
      ++vertices;
      continue;
    }
    if (n < 3) fail(number, "a face needs at least 3 vertices");
    for (std::size_t k = 1; k <= n; ++k) {
      const std::string index = tokens[k].substr(0, tokens[k].find('/'));
      long long v = 0;
      const char* end = index.data() + index.size();
      const auto [ptr, ec] = std::from_chars(index.data(), end, v);
      const bool ok = !index.empty() && ec == std::errc() && ptr == end &&
                      ((v > 0 && v <= total) || (v < 0 && -v <= vertices));
      if (!ok) {
        fail(number, "face vertex '" + tokens[k] + "' is not one of the file's " +
                         std::to_string(total) + " vertices (" + std::to_string(vertices) +
                         " before this line)");
      }
    }
  }
}

void LoadObj(const std::filesystem::path& path, Verts& verts, Tris& tris) {
  if (!std::filesystem::exists(path)) {
    throw Error(ErrorCode::kNotFound, path.string() + ": mesh file not found");
  }
  const std::string text = ReadFile(path, std::size_t{1} << 30);
  CheckObjText(path, text);
  tinyobj::ObjReaderConfig config;
  config.triangulate = true;
  config.vertex_color = false;
  config.mtl_search_path = "";
  tinyobj::ObjReader reader;
  if (!reader.ParseFromString(text, "", config)) {
    std::string msg = reader.Error();
    while (!msg.empty() && (msg.back() == '\n' || msg.back() == '\r')) msg.pop_back();
    std::replace(msg.begin(), msg.end(), '\n', ' ');
    throw Error(ErrorCode::kFormat, path.string() + ": OBJ: " + msg);
  }
  const auto& attrib = reader.GetAttrib();
  const int base = static_cast<int>(verts.size());
  const int nv = static_cast<int>(attrib.vertices.size() / 3);
  for (int i = 0; i < nv; ++i) {
    const Eigen::Vector3f v(attrib.vertices[3 * i], attrib.vertices[3 * i + 1],
                            attrib.vertices[3 * i + 2]);
    if (!v.allFinite()) throw Error(ErrorCode::kFormat, path.string() + ": OBJ: non-finite vertex");
    verts.push_back(v);
  }
  for (const auto& shape : reader.GetShapes()) {
    const auto& idx = shape.mesh.indices;
    for (std::size_t f = 0; f + 2 < idx.size(); f += 3) {
      Eigen::Vector3i t(idx[f].vertex_index, idx[f + 1].vertex_index, idx[f + 2].vertex_index);
      if ((t.array() < 0).any() || (t.array() >= nv).any()) {
        throw Error(ErrorCode::kFormat, path.string() + ": OBJ: face index out of range");
      }
      tris.emplace_back(t.array() + base);
    }
  }
}

std::vector<Keyframe> ReadMotion(const YamlReader& r, const YAML::Node& node,
                                 const Keyframe& rest) {
  if (!node.IsSequence() || node.size() == 0) r.Fail(node, "motion must be a non-empty list");
  std::vector<Keyframe> keys;
  for (const auto& k : node) {
    r.CheckKeys(k, {"t", "position_m", "rotation_deg"}, "motion keyframe");
    Keyframe key = rest;
    if (!k["t"]) r.Fail(k, "motion keyframe needs t");
    key.time_s = r.Number(k["t"], "t", -1e6, 1e6);
    if (k["position_m"]) key.position_m = r.Vec3(k["position_m"], "position_m");
    if (k["rotation_deg"]) key.rotation_deg = r.Vec3(k["rotation_deg"], "rotation_deg");
    if (!keys.empty() && key.time_s <= keys.back().time_s) {
      r.Fail(k, "motion keyframe times must increase");
    }
    keys.push_back(key);
  }
  return keys;
}

Trajectory ReadPose(const YamlReader& r, const YAML::Node& node) {
  Keyframe rest;
  if (node["position_m"]) rest.position_m = r.Vec3(node["position_m"], "position_m");
  if (node["rotation_deg"]) rest.rotation_deg = r.Vec3(node["rotation_deg"], "rotation_deg");
  Trajectory t;
  if (node["motion"]) {
    t.keys = ReadMotion(r, node["motion"], rest);
  } else {
    t.keys = {rest};
  }
  return t;
}

}  // namespace

Eigen::Isometry3d Trajectory::At(double time_s) const {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  if (keys.empty()) return out;
  Keyframe k = keys.front();
  if (time_s >= keys.back().time_s) {
    k = keys.back();
  } else if (time_s > keys.front().time_s) {
    const auto it = std::upper_bound(keys.begin(), keys.end(), time_s,
                                     [](double t, const Keyframe& kf) { return t < kf.time_s; });
    const Keyframe& b = *it;
    const Keyframe& a = *(it - 1);
    const double w = (time_s - a.time_s) / (b.time_s - a.time_s);
    k.position_m = a.position_m + w * (b.position_m - a.position_m);
    k.rotation_deg = a.rotation_deg + w * (b.rotation_deg - a.rotation_deg);
  }
  out.linear() = EulerDeg(k.rotation_deg);
  out.translation() = k.position_m;
  return out;
}

bool Trajectory::IsStatic() const {
  for (std::size_t i = 1; i < keys.size(); ++i) {
    if (keys[i].position_m != keys[0].position_m || keys[i].rotation_deg != keys[0].rotation_deg) {
      return false;
    }
  }
  return true;
}

bool Lamp::OnAt(double time_s) const {
  bool on = schedule.empty() ? true : schedule.front().on;
  for (const LampSwitch& s : schedule) {
    if (s.time_s <= time_s) on = s.on;
  }
  return on;
}

void LoadMesh(const std::filesystem::path& path, std::vector<Eigen::Vector3f>& vertices,
              std::vector<Eigen::Vector3i>& triangles) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (ext == ".ply") {
    LoadPly(path, vertices, triangles);
  } else if (ext == ".obj") {
    LoadObj(path, vertices, triangles);
  } else {
    throw Error(ErrorCode::kFormat, path.string() + ": unsupported mesh type (use .ply or .obj)");
  }
}

Scene ParseScene(std::string_view yaml_text, const std::string& source,
                 const std::filesystem::path& base_dir, const SceneOverrides& overrides) {
  const YAML::Node root = internal::ParseYaml(std::string(yaml_text), source);
  Scene scene;
  {
    const YamlReader r0(source);
    if (!root.IsMap()) r0.FailAt(0, "a scene must be a YAML mapping");
    r0.CheckKeys(root,
                 {"name", "parameters", "duration_s", "ambient_irradiance_w_m2", "materials",
                  "objects", "lamps", "camera", "pan_unit"},
                 "scene");
    if (const YAML::Node p = root["parameters"]) {
      if (!p.IsMap()) r0.Fail(p, "parameters must be a mapping of name: number");
      for (const auto& kv : p) {
        const std::string key = r0.Key(kv.first, "parameters");
        scene.parameters[key] = r0.Number(kv.second, "parameter " + key);
      }
    }
  }
  for (const auto& [key, value] : overrides) {
    if (!scene.parameters.count(key)) {
      std::string known;
      for (const auto& kv : scene.parameters) known += (known.empty() ? "" : ", ") + kv.first;
      throw Error(ErrorCode::kInvalidArgument,
                  source + ": unknown scene parameter '" + key +
                      "' (declared: " + (known.empty() ? "none" : known) + ")");
    }
    try {
      std::size_t used = 0;
      const double v = std::stod(value, &used);
      if (used != value.size() || !std::isfinite(v)) throw std::invalid_argument(value);
      scene.parameters[key] = v;
    } catch (const std::exception&) {
      throw Error(ErrorCode::kInvalidArgument,
                  source + ": scene parameter " + key + " = '" + value + "' is not a number");
    }
  }
  const YamlReader r(source, &scene.parameters);
  scene.name =
      root["name"] ? r.String(root["name"], "name") : std::filesystem::path(source).stem().string();
  r.Read(root, "duration_s", scene.duration_s, 0, 1e6);
  r.Read(root, "ambient_irradiance_w_m2", scene.ambient_irradiance_w_m2, 0, 1e4);

  std::map<std::string, int> material_index;
  if (const YAML::Node mats = root["materials"]) {
    if (!mats.IsMap()) r.Fail(mats, "materials must be a mapping name: {albedo, ...}");
    for (const auto& kv : mats) {
      r.CheckKeys(kv.second, {"albedo", "specular", "shininess", "mirror", "emission_w_m2_sr"},
                  "material");
      Material m;
      m.name = r.Key(kv.first, "materials");
      r.Read(kv.second, "albedo", m.albedo, 0, 1);
      r.Read(kv.second, "specular", m.specular, 0, 1);
      r.Read(kv.second, "shininess", m.shininess, 1e-3, 1e5);
      r.Read(kv.second, "mirror", m.mirror, 0, 0.999);
      r.Read(kv.second, "emission_w_m2_sr", m.emission_w_m2_sr, 0, 1e9);
      material_index[m.name] = static_cast<int>(scene.materials.size());
      scene.materials.push_back(m);
    }
  }
  const YAML::Node objs = root["objects"];
  if (!objs || !objs.IsSequence()) r.FailAt(0, "scene needs an 'objects' list");
  // A small file can name an object or a mesh many times (YAML aliases): bounded, so that it
  // fails here instead of in the allocator. A mesh file named twice is read once.
  constexpr std::size_t kMaxObjects = 1 << 16;
  constexpr std::size_t kMaxTriangles = 1 << 23;
  if (objs.size() > kMaxObjects) {
    r.Fail(objs, "scene has " + std::to_string(objs.size()) + " objects, at most " +
                     std::to_string(kMaxObjects));
  }
  std::size_t triangles = 0;
  std::map<std::filesystem::path,
           std::pair<std::vector<Eigen::Vector3f>, std::vector<Eigen::Vector3i>>>
      meshes;
  for (const auto& o : objs) {
    r.CheckKeys(o,
                {"name", "type", "material", "size_m", "radius_m", "height_m", "file", "scale",
                 "position_m", "rotation_deg", "motion"},
                "object");
    SceneObject obj;
    obj.name =
        o["name"] ? r.String(o["name"], "name") : "object" + std::to_string(scene.objects.size());
    if (!o["type"]) r.Fail(o, "object '" + obj.name + "' needs a type");
    const std::string type = r.String(o["type"], "type");
    if (!o["material"]) r.Fail(o, "object '" + obj.name + "' needs a material");
    const std::string mat = r.String(o["material"], "material");
    if (!material_index.count(mat)) r.Fail(o["material"], "unknown material '" + mat + "'");
    obj.material = material_index[mat];
    auto need = [&](const char* key) {
      if (!o[key]) r.Fail(o, type + " '" + obj.name + "' needs " + key);
      return o[key];
    };
    if (type == "plane") {
      const Eigen::Vector2d s = r.Vec2(need("size_m"), "size_m");
      // The range of radius_m: smaller vanishes between rays, larger leaves float precision.
      if (!(s.array() >= kMinSizeM).all() || !(s.array() <= kMaxSizeM).all()) {
        r.Fail(o["size_m"], "size_m must be in [1e-06, 10000] m");
      }
      MakePlane(s, obj.vertices, obj.triangles);
    } else if (type == "box") {
      const Eigen::Vector3d s = r.Vec3(need("size_m"), "size_m");
      if (!(s.array() >= kMinSizeM).all() || !(s.array() <= kMaxSizeM).all()) {
        r.Fail(o["size_m"], "size_m must be in [1e-06, 10000] m");
      }
      MakeBox(s, obj.vertices, obj.triangles);
    } else if (type == "sphere") {
      MakeSphere(r.Number(need("radius_m"), "radius_m", kMinSizeM, kMaxSizeM), obj.vertices,
                 obj.triangles);
    } else if (type == "cylinder") {
      MakeCylinder(r.Number(need("radius_m"), "radius_m", kMinSizeM, kMaxSizeM),
                   r.Number(need("height_m"), "height_m", kMinSizeM, kMaxSizeM), obj.vertices,
                   obj.triangles);
    } else if (type == "mesh") {
      std::filesystem::path file = r.String(need("file"), "file");
      if (file.is_relative()) file = base_dir / file;
      auto cached = meshes.find(file);
      if (cached == meshes.end()) {
        try {
          LoadMesh(file, obj.vertices, obj.triangles);
        } catch (const Error& e) {
          r.Fail(o["file"], e.what());
        }
        cached = meshes.emplace(file, std::make_pair(obj.vertices, obj.triangles)).first;
      } else {
        obj.vertices = cached->second.first;
        obj.triangles = cached->second.second;
      }
      if (obj.triangles.empty()) r.Fail(o["file"], "mesh has no triangles");
      const double scale = o["scale"] ? r.Number(o["scale"], "scale", 1e-9, 1e9) : 1.0;
      for (auto& v : obj.vertices) {
        v *= static_cast<float>(scale);
        if (!(v.array().abs() <= static_cast<float>(kMaxSizeM)).all()) {
          r.Fail(o["file"], "mesh vertex beyond 10000 m after scale " + std::to_string(scale) +
                                " (or not finite)");
        }
      }
    } else {
      r.Fail(o["type"], "unknown object type '" + type + "' (plane, box, sphere, cylinder, mesh)");
    }
    obj.motion = ReadPose(r, o);
    triangles += obj.triangles.size();
    if (triangles > kMaxTriangles) {
      r.Fail(o, "scene has more than " + std::to_string(kMaxTriangles) + " triangles (at object '" +
                    obj.name + "')");
    }
    scene.objects.push_back(std::move(obj));
  }
  if (const YAML::Node c = root["camera"]) {
    r.CheckKeys(c, {"position_m", "rotation_deg", "motion"}, "camera");
    scene.camera = ReadPose(r, c);
  } else {
    scene.camera.keys = {Keyframe{}};
  }
  if (const YAML::Node p = root["pan_unit"]) {
    r.CheckKeys(p, {"axis", "camera_offset_m", "schedule"}, "pan_unit");
    if (p["axis"]) {
      const Eigen::Vector3d a = r.Vec3(p["axis"], "axis");
      if (a.norm() < 1e-9) r.Fail(p["axis"], "pan axis must not be zero");
      scene.pan_unit.axis = a.normalized();
    }
    if (p["camera_offset_m"])
      scene.pan_unit.camera_offset_m = r.Vec3(p["camera_offset_m"], "camera_offset_m");
    if (const YAML::Node s = p["schedule"]) {
      if (!s.IsSequence()) r.Fail(s, "pan schedule must be a list of {t, angle_deg}");
      for (const auto& k : s) {
        r.CheckKeys(k, {"t", "angle_deg"}, "pan schedule entry");
        if (!k["t"] || !k["angle_deg"]) r.Fail(k, "pan schedule entry needs t and angle_deg");
        PanKey key{r.Number(k["t"], "t", -1e6, 1e6),
                   r.Number(k["angle_deg"], "angle_deg", -3600, 3600)};
        if (!scene.pan_schedule.empty() && key.time_s <= scene.pan_schedule.back().time_s) {
          r.Fail(k, "pan schedule times must increase");
        }
        scene.pan_schedule.push_back(key);
      }
    }
  }
  scene.lamp_bulb_begin = static_cast<int>(scene.objects.size());
  if (const YAML::Node lamps = root["lamps"]) {
    if (!lamps.IsSequence()) r.Fail(lamps, "lamps must be a list");
    for (const auto& l : lamps) {
      r.CheckKeys(l, {"name", "position_m", "ir_power_w", "bulb_radius_m", "schedule"}, "lamp");
      Lamp lamp;
      lamp.name =
          l["name"] ? r.String(l["name"], "name") : "lamp" + std::to_string(scene.lamps.size());
      if (!l["position_m"]) r.Fail(l, "lamp '" + lamp.name + "' needs position_m");
      lamp.position_m = r.Vec3(l["position_m"], "position_m");
      r.Read(l, "ir_power_w", lamp.ir_power_w, 0, 1e6);
      r.Read(l, "bulb_radius_m", lamp.bulb_radius_m, 1e-4, 10);
      if (const YAML::Node s = l["schedule"]) {
        if (!s.IsSequence()) r.Fail(s, "lamp schedule must be a list of {t, on}");
        for (const auto& k : s) {
          r.CheckKeys(k, {"t", "on"}, "lamp schedule entry");
          if (!k["t"] || !k["on"]) r.Fail(k, "lamp schedule entry needs t and on");
          LampSwitch sw{r.Number(k["t"], "t", -1e6, 1e6), r.Bool(k["on"], "on")};
          if (!lamp.schedule.empty() && sw.time_s <= lamp.schedule.back().time_s) {
            r.Fail(k, "lamp schedule times must increase");
          }
          lamp.schedule.push_back(sw);
        }
      }
      // The bulb: a glowing sphere whose radiance carries the lamp's power, P / (4 pi^2 r^2).
      Material bulb;
      bulb.name = "bulb:" + lamp.name;
      bulb.albedo = 0.8;
      bulb.emission_w_m2_sr =
          lamp.ir_power_w / (4 * kPi * kPi * lamp.bulb_radius_m * lamp.bulb_radius_m);
      SceneObject obj;
      obj.name = bulb.name;
      obj.material = static_cast<int>(scene.materials.size());
      scene.materials.push_back(bulb);
      MakeSphere(lamp.bulb_radius_m, obj.vertices, obj.triangles);
      Keyframe k;
      k.position_m = lamp.position_m;
      obj.motion.keys = {k};
      scene.objects.push_back(std::move(obj));
      scene.lamps.push_back(std::move(lamp));
    }
  }
  if (scene.objects.empty()) r.FailAt(0, "scene has no objects");
  return scene;
}

Scene LoadScene(const std::filesystem::path& path, const SceneOverrides& overrides) {
  const std::string text = ReadFile(path, std::size_t{16} << 20);
  return ParseScene(text, path.string(), path.parent_path(), overrides);
}

std::vector<std::string> BuiltinSceneNames() {
  std::vector<std::string> names;
  for (int i = 0; i < internal::kEmbeddedFileCount; ++i) {
    const std::string p = internal::kEmbeddedFiles[i].path;
    if (p.find('/') == std::string::npos && p.size() > 5 && p.substr(p.size() - 5) == ".yaml") {
      names.push_back(p.substr(0, p.size() - 5));
    }
  }
  return names;
}

Scene LoadBuiltinScene(const std::string& name, const SceneOverrides& overrides) {
  for (int i = 0; i < internal::kEmbeddedFileCount; ++i) {
    if (internal::kEmbeddedFiles[i].path == name + ".yaml") {
      return ParseScene(internal::kEmbeddedFiles[i].content, "<builtin>/" + name + ".yaml", {},
                        overrides);
    }
  }
  std::string known;
  for (const auto& n : BuiltinSceneNames()) known += (known.empty() ? "" : ", ") + n;
  throw Error(ErrorCode::kNotFound,
              "unknown scene '" + name + "' (built-in: " + known + "; or a path to a .yaml file)");
}

Scene StaticView(Scene scene) {
  const auto freeze = [](Trajectory& trajectory) {
    if (trajectory.keys.empty()) return;
    if (trajectory.keys.front().time_s < 0) {
      throw Error(ErrorCode::kInvalidArgument,
                  "StaticView: a trajectory starts before t = 0 (its pose there is interpolated)");
    }
    trajectory.keys.resize(1);
  };
  for (SceneObject& object : scene.objects) freeze(object.motion);
  freeze(scene.camera);
  if (!scene.pan_schedule.empty()) scene.pan_schedule.resize(1);
  for (Lamp& lamp : scene.lamps) lamp.schedule = {{0.0, lamp.OnAt(0.0)}};
  scene.duration_s = 0.0;
  return scene;
}

Scene ResolveScene(const std::string& name_or_path, const SceneOverrides& overrides) {
  const std::filesystem::path p(name_or_path);
  const bool file_name = p.extension() == ".yaml" || p.extension() == ".yml";
  if (!file_name) {
    // Embedded scenes outside the built-in list (calibration/scattering-card) are named by
    // their folder too; a file on disk of that relative name would need its extension.
    for (int i = 0; i < internal::kEmbeddedFileCount; ++i) {
      if (internal::kEmbeddedFiles[i].path == name_or_path + ".yaml") {
        return LoadBuiltinScene(name_or_path, overrides);
      }
    }
  }
  if (name_or_path.find('/') != std::string::npos || file_name) return LoadScene(p, overrides);
  return LoadBuiltinScene(name_or_path, overrides);
}

std::pair<std::string, SceneOverrides> ParseSceneSpec(const std::string& spec) {
  const auto q = spec.find('?');
  std::pair<std::string, SceneOverrides> out;
  out.first = spec.substr(0, q);
  if (out.first.empty())
    throw Error(ErrorCode::kInvalidArgument, "scene spec '" + spec + "' has no scene name");
  if (q == std::string::npos) return out;
  std::string rest = spec.substr(q + 1);
  std::size_t start = 0;
  while (start <= rest.size()) {
    const auto amp = rest.find('&', start);
    const std::string kv =
        rest.substr(start, amp == std::string::npos ? std::string::npos : amp - start);
    const auto eq = kv.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == kv.size()) {
      throw Error(ErrorCode::kInvalidArgument,
                  "scene spec '" + spec + "': expected key=value, got '" + kv + "'");
    }
    out.second[kv.substr(0, eq)] = kv.substr(eq + 1);
    if (amp == std::string::npos) break;
    start = amp + 1;
  }
  return out;
}

}  // namespace tofcam::sim

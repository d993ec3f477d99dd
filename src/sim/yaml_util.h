#pragma once
// Internal helpers for reading YAML with errors that name the source, the line and the problem.

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <map>
#include <set>
#include <string>

#include "../core/yaml_checks.h"
#include "tofcam/core/error.h"

namespace tofcam::sim::internal {

class YamlReader {
 public:
  YamlReader(std::string source, const std::map<std::string, double>* parameters = nullptr)
      : source_(std::move(source)), parameters_(parameters) {}

  [[noreturn]] void Fail(const YAML::Node& node, const std::string& problem) const {
    const YAML::Mark mark = node.Mark();
    std::string where = source_;
    if (mark.line >= 0) where += ":" + std::to_string(mark.line + 1);
    throw Error(ErrorCode::kFormat, where + ": " + problem);
  }
  [[noreturn]] void FailAt(int line0, const std::string& problem) const {
    throw Error(ErrorCode::kFormat, source_ + ":" + std::to_string(line0 + 1) + ": " + problem);
  }

  /// A mapping's key as text; kFormat for a key that is a sequence or a mapping ("? [a, b]").
  std::string Key(const YAML::Node& key, const std::string& what) const {
    if (!key.IsScalar()) Fail(key, "keys of " + what + " must be plain names");
    return key.Scalar();
  }

  /// Rejects keys not in `allowed` (typos must not silently fall back to defaults).
  void CheckKeys(const YAML::Node& map, const std::set<std::string>& allowed,
                 const std::string& what) const {
    if (!map.IsMap()) Fail(map, what + " must be a mapping");
    for (const auto& kv : map) {
      const std::string key = Key(kv.first, what);
      if (!allowed.count(key)) Fail(kv.first, "unknown key '" + key + "' in " + what);
    }
  }

  double Number(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) Fail(node, what + " must be a number");
    std::string s = node.Scalar();
    double sign = 1.0;
    if (!s.empty() && s[0] == '-' && s.size() > 1 && s[1] == '$') {
      sign = -1.0;
      s = s.substr(1);
    }
    if (!s.empty() && s[0] == '$') {
      const std::string name = s.substr(1);
      if (parameters_ == nullptr || !parameters_->count(name)) {
        Fail(node, what + " refers to undeclared parameter '" + name + "'");
      }
      return sign * parameters_->at(name);
    }
    double value = 0.0;
    try {
      std::size_t used = 0;
      value = std::stod(s, &used);
      if (used != s.size()) throw std::invalid_argument(s);
    } catch (const std::exception&) {
      Fail(node, what + " must be a number, got '" + node.Scalar() + "'");
    }
    if (!std::isfinite(value)) Fail(node, what + " must be finite");
    return value;
  }
  double Number(const YAML::Node& node, const std::string& what, double lo, double hi) const {
    const double v = Number(node, what);
    if (v < lo || v > hi) {
      Fail(node, what + " = " + node.Scalar() + " out of range [" + Fmt(lo) + ", " + Fmt(hi) + "]");
    }
    return v;
  }
  void Read(const YAML::Node& map, const char* key, double& out, double lo, double hi) const {
    if (const YAML::Node n = map[key]) out = Number(n, key, lo, hi);
  }
  void ReadInt(const YAML::Node& map, const char* key, int& out, int lo, int hi) const {
    if (const YAML::Node n = map[key]) {
      const double v = Number(n, key, lo, hi);
      if (v != std::floor(v)) Fail(n, std::string(key) + " must be an integer");
      out = static_cast<int>(v);
    }
  }
  bool Bool(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) Fail(node, what + " must be true or false");
    const std::string& s = node.Scalar();
    if (s == "true" || s == "on" || s == "yes") return true;
    if (s == "false" || s == "off" || s == "no") return false;
    Fail(node, what + " must be true or false, got '" + s + "'");
  }
  std::string String(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) Fail(node, what + " must be a string");
    return node.Scalar();
  }
  Eigen::Vector3d Vec3(const YAML::Node& node, const std::string& what) const {
    if (!node.IsSequence() || node.size() != 3) Fail(node, what + " must be a list of 3 numbers");
    return {Number(node[0], what), Number(node[1], what), Number(node[2], what)};
  }
  Eigen::Vector2d Vec2(const YAML::Node& node, const std::string& what) const {
    if (!node.IsSequence() || node.size() != 2) Fail(node, what + " must be a list of 2 numbers");
    return {Number(node[0], what), Number(node[1], what)};
  }
  const std::string& source() const { return source_; }

  static std::string Fmt(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
  }

 private:
  std::string source_;
  const std::map<std::string, double>* parameters_;
};

/// Parses YAML text, turning yaml-cpp syntax errors into Error(kFormat) with source and line.
/// A key repeated within one mapping is Error(kFormat) too (tofcam::internal::RejectDuplicateKeys).
inline YAML::Node ParseYaml(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw Error(ErrorCode::kFormat,
                source + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg);
  }
  tofcam::internal::RejectDuplicateKeys(root, source);
  return root;
}

/// The built-in embedded files: (relative path under scenes/, content).
struct EmbeddedFile {
  const char* path;
  const char* content;
};
extern const EmbeddedFile kEmbeddedFiles[];
extern const int kEmbeddedFileCount;

}  // namespace tofcam::sim::internal

// YAML configuration into Options structs (after Drake's LoadYamlFile / yaml_read_archive).
//
// An Options struct lists its fields once, with inline documented defaults:
//
//   struct Options {
//     int particles = 30;         // number of particles
//     double resolution = 0.05;   // [m] grid cell size
//     template <class Archive> void Serialize(Archive* a) {
//       a->Visit("particles", &particles);
//       a->Visit("resolution", &resolution);
//     }
//     fl::Status Validate() const;   // optional: range checks with a clear message
//   };
//
//   auto opts = fl::LoadYamlFile<Options>("config/rbpf.yaml");          // whole file
//   auto opts = fl::LoadYamlFile<Options>("config/system.yaml", "rbpf"); // one top-level key
//
// Keys that are absent keep their defaults. Unknown keys, values of the wrong type and a
// missing or unparsable file throw fl::ConfigError naming the file, line, key and expected
// type. Supported field types: bool, int, int64_t, double, float, std::string,
// std::vector<of those>, and nested structs with their own Serialize.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/status.hpp"

namespace fl {

class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

namespace internal {

template <class T, class = void>
struct HasSerialize : std::false_type {};
template <class T>
struct HasSerialize<T, std::void_t<decltype(std::declval<T&>().Serialize(
                           static_cast<struct YamlProbeArchive*>(nullptr)))>> : std::true_type {};

struct YamlProbeArchive {
  template <class V>
  void Visit(const char*, V*) {}
};

template <class T, class = void>
struct HasValidate : std::false_type {};
template <class T>
struct HasValidate<T, std::void_t<decltype(std::declval<const T&>().Validate())>> : std::true_type {
};

template <class T>
struct IsVector : std::false_type {};
template <class T, class A>
struct IsVector<std::vector<T, A>> : std::true_type {};

template <class T>
const char* TypeName() {
  if constexpr (std::is_same_v<T, bool>) return "a boolean (true/false)";
  if constexpr (std::is_integral_v<T>) return "an integer";
  if constexpr (std::is_floating_point_v<T>) return "a number";
  if constexpr (std::is_same_v<T, std::string>) return "a string";
  if constexpr (IsVector<T>::value) return "a list";
  return "a map";
}

// Closest known key by edit distance, for "did you mean" hints ("" if none is close).
std::string ClosestKey(const std::string& key, const std::vector<std::string>& known);

}  // namespace internal

// Reads one YAML map into a struct; see the file comment.
class YamlReadArchive {
 public:
  YamlReadArchive(YAML::Node node, std::string file, std::string prefix)
      : node_(std::move(node)), file_(std::move(file)), prefix_(std::move(prefix)) {}

  template <class T>
  void Visit(const char* name, T* value) {
    known_.push_back(name);
    const YAML::Node child = node_[name];
    if (!child.IsDefined() || child.IsNull()) return;  // absent: keep the default
    Read(child, Qualified(name), value);
  }

  // Throws ConfigError if the map holds keys no Visit asked for.
  void CheckNoUnknownKeys() const;

  template <class T>
  void ReadRoot(T* value) {
    if (!node_.IsMap()) {
      throw ConfigError(Where(node_) + "expected a map of options" +
                        (prefix_.empty() ? std::string() : " under '" + prefix_ + "'"));
    }
    value->Serialize(this);
    CheckNoUnknownKeys();
  }

 private:
  std::string Qualified(const std::string& name) const {
    return prefix_.empty() ? name : prefix_ + "." + name;
  }
  std::string Where(const YAML::Node& n) const;
  [[noreturn]] void TypeError(const YAML::Node& n, const std::string& key,
                              const char* expected) const;

  template <class T>
  void Read(const YAML::Node& n, const std::string& key, T* value) {
    if constexpr (internal::HasSerialize<T>::value) {
      YamlReadArchive sub(n, file_, key);
      sub.ReadRoot(value);
    } else if constexpr (internal::IsVector<T>::value) {
      if (!n.IsSequence()) TypeError(n, key, internal::TypeName<T>());
      T out;
      for (size_t i = 0; i < n.size(); ++i) {
        typename T::value_type v{};
        Read(n[i], key + "[" + std::to_string(i) + "]", &v);
        out.push_back(v);
      }
      *value = std::move(out);
    } else {
      if (!n.IsScalar()) TypeError(n, key, internal::TypeName<T>());
      if constexpr (std::is_same_v<T, std::string>) {
        *value = n.Scalar();
      } else {
        // yaml-cpp's own conversion, but reject e.g. 3.5 for an int or "abc" for a number.
        T v{};
        if (!YAML::convert<T>::decode(n, v)) TypeError(n, key, internal::TypeName<T>());
        *value = v;
      }
    }
  }

  YAML::Node node_;
  std::string file_;
  std::string prefix_;
  std::vector<std::string> known_;
};

// Writes a struct as YAML (e.g. to print the defaults: `fl-xxx --print-config`).
class YamlWriteArchive {
 public:
  explicit YamlWriteArchive(YAML::Emitter* out) : out_(out) {}
  template <class T>
  void Visit(const char* name, T* value) {
    *out_ << YAML::Key << name << YAML::Value;
    Write(*value);
  }

 private:
  template <class T>
  void Write(const T& v) {
    if constexpr (internal::HasSerialize<T>::value) {
      *out_ << YAML::BeginMap;
      const_cast<T&>(v).Serialize(this);
      *out_ << YAML::EndMap;
    } else if constexpr (internal::IsVector<T>::value) {
      *out_ << YAML::Flow << YAML::BeginSeq;
      for (const auto& e : v) Write(e);
      *out_ << YAML::EndSeq;
    } else if constexpr (std::is_same_v<T, float>) {
      *out_ << FormatFloat(v);  // shortest round-trip text, not 9 or 17 digits
    } else if constexpr (std::is_floating_point_v<T>) {
      *out_ << FormatDouble(static_cast<double>(v));
    } else {
      *out_ << v;
    }
  }
  YAML::Emitter* out_;
};

// Loads a node (already parsed) into T, then runs T::Validate() if it exists.
template <class T>
T LoadYamlNode(const YAML::Node& root, const std::string& file, const std::string& child_key = "") {
  T value{};
  YAML::Node node = root;
  if (!child_key.empty()) {
    if (!root.IsMap() || !root[child_key].IsDefined()) {
      throw ConfigError(file + ": no top-level key '" + child_key + "'; add a '" + child_key +
                        ":' section (an empty one keeps every default)");
    }
    node = root[child_key];
    if (node.IsNull()) node = YAML::Node(YAML::NodeType::Map);
  }
  if (node.IsNull()) node = YAML::Node(YAML::NodeType::Map);  // empty file: all defaults
  YamlReadArchive archive(node, file, child_key);
  archive.ReadRoot(&value);
  if constexpr (internal::HasValidate<T>::value) {
    const Status s = value.Validate();
    if (!s.ok()) {
      throw ConfigError(file + (child_key.empty() ? "" : " (" + child_key + ")") +
                        ": invalid value: " + s.message());
    }
  }
  return value;
}

// Parses YAML text; `name` stands for the file in messages.
YAML::Node ParseYamlString(const std::string& text, const std::string& name);
// Parses a YAML file; throws ConfigError naming the file if missing or malformed.
YAML::Node ParseYamlFile(const std::string& path);

template <class T>
T LoadYamlFile(const std::string& path, const std::string& child_key = "") {
  return LoadYamlNode<T>(ParseYamlFile(path), path, child_key);
}

template <class T>
T LoadYamlString(const std::string& text, const std::string& child_key = "",
                 const std::string& name = "<string>") {
  return LoadYamlNode<T>(ParseYamlString(text, name), name, child_key);
}

template <class T>
std::string SaveYamlString(const T& value) {
  YAML::Emitter out;
  out << YAML::BeginMap;
  YamlWriteArchive archive(&out);
  const_cast<T&>(value).Serialize(&archive);
  out << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

}  // namespace fl

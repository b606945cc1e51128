#include "fusionloc/common/yaml_options.hpp"

#include <gtest/gtest.h>

#include <fstream>

#include "test_paths.hpp"

namespace fl {
namespace {

struct MatcherOptions {
  double max_range = 10.0;  // [m]
  int iterations = 20;
  template <class A>
  void Serialize(A* a) {
    a->Visit("max_range", &max_range);
    a->Visit("iterations", &iterations);
  }
};

struct DemoOptions {
  int particles = 30;
  double resolution = 0.05;
  bool use_icp = true;
  std::string name = "rbpf";
  int64_t start_utime = 0;
  std::vector<double> sigmas = {0.1, 0.2};
  MatcherOptions matcher;
  template <class A>
  void Serialize(A* a) {
    a->Visit("particles", &particles);
    a->Visit("resolution", &resolution);
    a->Visit("use_icp", &use_icp);
    a->Visit("name", &name);
    a->Visit("start_utime", &start_utime);
    a->Visit("sigmas", &sigmas);
    a->Visit("matcher", &matcher);
  }
  Status Validate() const {
    if (particles < 1)
      return Status::Error("particles must be >= 1, got " + std::to_string(particles));
    return Status::Ok();
  }
};

std::string ErrorOf(const std::string& yaml) {
  try {
    LoadYamlString<DemoOptions>(yaml, "", "demo.yaml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(YamlOptions, DefaultsAndValues) {
  const auto d = LoadYamlString<DemoOptions>("");
  EXPECT_EQ(d.particles, 30);
  EXPECT_EQ(d.matcher.iterations, 20);
  const auto o = LoadYamlString<DemoOptions>(
      "particles: 50\nresolution: 0.1\nuse_icp: false\nname: x\nstart_utime: 1700000000000000\n"
      "sigmas: [1, 2, 3]\nmatcher: {max_range: 5.5}\n");
  EXPECT_EQ(o.particles, 50);
  EXPECT_DOUBLE_EQ(o.resolution, 0.1);
  EXPECT_FALSE(o.use_icp);
  EXPECT_EQ(o.name, "x");
  EXPECT_EQ(o.start_utime, 1700000000000000);
  EXPECT_EQ(o.sigmas, (std::vector<double>{1, 2, 3}));
  EXPECT_DOUBLE_EQ(o.matcher.max_range, 5.5);
  EXPECT_EQ(o.matcher.iterations, 20);
}

TEST(YamlOptions, UnknownKeyNamesFileLineKeyAndSuggestion) {
  const std::string e = ErrorOf("particles: 5\npartcles: 10\n");
  EXPECT_NE(e.find("demo.yaml:2:1"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown key 'partcles'"), std::string::npos) << e;
  EXPECT_NE(e.find("did you mean 'particles'"), std::string::npos) << e;
}

// Found by fuzzing (tests/fuzz/regressions/yaml_options/non-scalar-key): a key that is itself
// a list or a map escaped as a yaml-cpp conversion exception instead of a ConfigError.
TEST(YamlOptions, AKeyThatIsAListOrAMapIsAConfigError) {
  EXPECT_NE(ErrorOf("[a, b]: 1\n").find("demo.yaml:1"), std::string::npos);
  EXPECT_NE(ErrorOf("? {x: 1}\n: 2\n").find("option keys are plain names"), std::string::npos);
}

TEST(YamlOptions, UnknownNestedKeyIsQualified) {
  const std::string e = ErrorOf("matcher:\n  max_rnge: 3\n");
  EXPECT_NE(e.find("unknown key 'matcher.max_rnge'"), std::string::npos) << e;
}

TEST(YamlOptions, WrongTypeNamesKeyAndExpectedType) {
  std::string e = ErrorOf("particles: many\n");
  EXPECT_NE(e.find("demo.yaml:1:12: key 'particles' expects an integer, got 'many'"),
            std::string::npos)
      << e;
  e = ErrorOf("particles: 3.5\n");
  EXPECT_NE(e.find("expects an integer, got '3.5'"), std::string::npos) << e;
  e = ErrorOf("resolution: [1]\n");
  EXPECT_NE(e.find("key 'resolution' expects a number, got a list"), std::string::npos) << e;
  e = ErrorOf("use_icp: maybe\n");
  EXPECT_NE(e.find("expects a boolean"), std::string::npos) << e;
  e = ErrorOf("sigmas: [1, x]\n");
  EXPECT_NE(e.find("key 'sigmas[1]' expects a number, got 'x'"), std::string::npos) << e;
  e = ErrorOf("matcher: 3\n");
  EXPECT_NE(e.find("expected a map of options under 'matcher'"), std::string::npos) << e;
}

TEST(YamlOptions, ValidateRunsAfterLoading) {
  const std::string e = ErrorOf("particles: 0\n");
  EXPECT_NE(e.find("demo.yaml: invalid value: particles must be >= 1, got 0"), std::string::npos)
      << e;
}

TEST(YamlOptions, MissingFileAndSyntaxError) {
  try {
    LoadYamlFile<DemoOptions>("/no/such/config.yaml");
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("config file '/no/such/config.yaml' not found"),
              std::string::npos);
  }
  const std::string e = ErrorOf("particles: [1,\n");
  EXPECT_NE(e.find("YAML syntax error"), std::string::npos) << e;
}

TEST(YamlOptions, ChildKeyOfAFile) {
  test::TempDir dir;
  const std::string path = dir.file("system.yaml");
  std::ofstream(path) << "demo:\n  particles: 7\nother:\n  anything: 1\n";
  EXPECT_EQ(LoadYamlFile<DemoOptions>(path, "demo").particles, 7);
  EXPECT_THROW(LoadYamlFile<DemoOptions>(path, "absent"), ConfigError);
}

TEST(YamlOptions, SaveThenLoadIsIdentity) {
  DemoOptions o;
  o.particles = 12;
  o.sigmas = {4, 5};
  o.matcher.iterations = 3;
  const auto back = LoadYamlString<DemoOptions>(SaveYamlString(o));
  EXPECT_EQ(back.particles, 12);
  EXPECT_EQ(back.sigmas, o.sigmas);
  EXPECT_EQ(back.matcher.iterations, 3);
}

}  // namespace
}  // namespace fl

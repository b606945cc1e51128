#include "fusionloc/bench/bench.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "test_paths.hpp"

namespace fl::bench {
namespace {

Report MakeReport(double ate) {
  Report r("demo");
  Run a;
  a.name = "intel";
  a.input = "/data/intel.log";
  a.Add("ate_rmse_m", ate).Add("items", 910);
  r.AddRun(a);
  return r;
}

TEST(Bench, StatsArePercentilesOfTheValues) {
  std::vector<double> v;
  for (int i = 1; i <= 101; ++i) v.push_back(i);
  const Stats s = ComputeStats(v);
  EXPECT_DOUBLE_EQ(s.mean, 51);
  EXPECT_DOUBLE_EQ(s.median, 51);
  EXPECT_DOUBLE_EQ(s.p95, 96);
  EXPECT_DOUBLE_EQ(s.max, 101);
  EXPECT_EQ(s.count, 101u);
}

TEST(Bench, JsonHasTheCommonShape) {
  const std::string j = MakeReport(0.031).Json("./fusionloc bench demo");
  EXPECT_NE(j.find("\"bench\": \"demo\""), std::string::npos) << j;
  EXPECT_NE(j.find("\"machine\": {"), std::string::npos);
  EXPECT_NE(j.find("{\"name\": \"intel\", \"input\": \"/data/intel.log\", \"metrics\": "
                   "{\"ate_rmse_m\": 0.031, \"items\": 910}}"),
            std::string::npos)
      << j;
}

TEST(Bench, RecordReplacesOnlyItsOwnSection) {
  test::TempDir dir;
  const std::string md = dir.file("B.md");
  std::ofstream(md)
      << "# Benchmarks\n\nintro\n\n<!-- bench:other:begin -->\nX\n<!-- bench:other:end -->\n";
  MakeReport(0.5).RecordInMarkdown(md, "cmd1");
  MakeReport(0.25).RecordInMarkdown(md, "cmd2");
  std::ifstream in(md);
  const std::string text((std::istreambuf_iterator<char>(in)), {});
  EXPECT_NE(text.find("intro"), std::string::npos);
  EXPECT_NE(text.find("<!-- bench:other:begin -->\nX\n"), std::string::npos);
  EXPECT_EQ(text.find("cmd1"), std::string::npos);
  EXPECT_NE(text.find("Command: `cmd2`"), std::string::npos);
  EXPECT_NE(text.find("| intel | 0.25 | 910 |"), std::string::npos) << text;
}

TEST(Bench, PeakRssIsPositive) { EXPECT_GT(PeakRssMb(), 0.0); }

}  // namespace
}  // namespace fl::bench

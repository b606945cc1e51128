#include "fusionloc/fusion/g2o_reader.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "test_paths.hpp"

namespace fl::fusion {
namespace {

Status Parse(const std::string& text, G2oGraph* g) {
  std::istringstream in(text);
  return ReadG2o(in, "t.g2o", g);
}

TEST(FusionG2oReader, Reads2dFileWithUpperTriangularInformation) {
  fl::test::TempDir dir;
  {
    std::ofstream out(dir.file("tiny.g2o"));
    out << "# a comment\n\n"
        << "VERTEX_SE2 0 0 0 0\n"
        << "VERTEX_SE2 1 1.0 0.5 4.0\n"  // angle wrapped on reading
        << "EDGE_SE2 0 1 1 0.5 0.1 10 1 2 20 3 30\n";
  }
  G2oGraph g;
  const Status s = ReadG2oFile(dir.file("tiny.g2o"), &g);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_FALSE(g.is_3d());
  ASSERT_EQ(g.poses2.size(), 2u);
  EXPECT_NEAR(g.poses2.at(1)[2], 4.0 - 2 * M_PI, 1e-12);
  ASSERT_EQ(g.edges2.size(), 1u);
  Eigen::Matrix3d expected;
  expected << 10, 1, 2, 1, 20, 3, 2, 3, 30;
  EXPECT_EQ(g.edges2[0].information, expected);
  EXPECT_EQ(g.edges2[0].id_j, 1);
}

TEST(FusionG2oReader, Reads3dFileWith21InformationEntries) {
  std::ostringstream t;
  t << "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n"
    << "VERTEX_SE3:QUAT 1 1 2 3 0 0 0 2\n"  // quaternion normalised
    << "EDGE_SE3:QUAT 0 1 1 2 3 0 0 0 1";
  for (int k = 0; k < 21; ++k) t << " " << (k + 1);
  t << "\n";
  G2oGraph g;
  const Status s = Parse(t.str(), &g);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(g.is_3d());
  EXPECT_NEAR(g.poses3.at(1).q.w(), 1.0, 1e-12);
  const auto& info = g.edges3[0].information;
  EXPECT_EQ(info(0, 0), 1);
  EXPECT_EQ(info(0, 5), 6);
  EXPECT_EQ(info(5, 0), 6);
  EXPECT_EQ(info(1, 1), 7);
  EXPECT_EQ(info(5, 5), 21);
}

void ExpectError(const std::string& text, const std::string& needle) {
  G2oGraph g;
  const Status s = Parse(text, &g);
  ASSERT_FALSE(s.ok()) << "accepted: " << text;
  EXPECT_NE(s.message().find(needle), std::string::npos) << s.message();
}

TEST(FusionG2oReader, MalformedLinesNameFileAndLine) {
  ExpectError("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0\n", "t.g2o:2:");
  ExpectError("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 zero 0\n", "'zero' is not a finite number");
  ExpectError("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 nan 0\n", "not a finite number");
  ExpectError("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 0 1 0 0\n", "duplicate vertex id 0");
  ExpectError("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0 7\n", "extra field");
  ExpectError("VERTEX_SE2 0 0 0 0\nVERTEX_XY 1 0 0\n", "unknown tag");
  ExpectError("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 5 1 0 0 1 0 0 1 0 1\n",
              "t.g2o:2: edge refers to vertex 5");
  ExpectError("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0\n", "t.g2o:3:");
  ExpectError("VERTEX_SE2 -1 0 0 0\n", "not a non-negative integer");
  ExpectError("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0\n", "quaternion is zero");
  ExpectError("VERTEX_SE2 0 0 0 0\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n", "mixes 2D and 3D");
  ExpectError("# only a comment\n", "no VERTEX_SE2");
}

TEST(FusionG2oReader, MissingFileIsAClearError) {
  G2oGraph g;
  const Status s = ReadG2oFile("/nonexistent/x.g2o", &g);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("/nonexistent/x.g2o"), std::string::npos);
}

}  // namespace
}  // namespace fl::fusion

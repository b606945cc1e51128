#include "fusionloc/common/state_buffer.hpp"

#include <gtest/gtest.h>

#include <limits>

namespace fl {
namespace {

TEST(StateBuffer, ValuesComeBackAsWritten) {
  StateWriter w;
  w.Begin("TESTSTAT", 3);
  w.Put(int64_t{-42});
  w.Put(std::numeric_limits<double>::denorm_min());
  w.Put(std::string("two\0words", 9));
  w.Put(Pose2(1.5, -2.25, 0.125));
  Eigen::Matrix<double, 2, 3> m;
  m << 1, 2, 3, 4, 5, 6;
  w.Put(m);
  w.PutCount(7);
  const std::vector<uint8_t> bytes = w.Release();

  StateReader r(bytes.data(), bytes.size());
  r.Begin("TESTSTAT", 3);
  EXPECT_EQ(r.Get<int64_t>("a"), -42);
  EXPECT_EQ(r.Get<double>("b"), std::numeric_limits<double>::denorm_min());
  EXPECT_EQ(r.GetString("c"), std::string("two\0words", 9));
  const Pose2 p = r.GetPose2("d");
  EXPECT_EQ(p.x, 1.5);
  EXPECT_EQ(p.y, -2.25);
  EXPECT_EQ(p.theta, 0.125);
  Eigen::Matrix<double, 2, 3> back;
  r.Get(&back, "e");
  EXPECT_EQ(back, m);
  EXPECT_THROW(r.Count(1, "seven things"), StateError);  // 7 bytes are not left
  EXPECT_TRUE(r.at_end());
  r.End("test state");
}

TEST(StateBuffer, DamageIsAnErrorNamingTheByteOffset) {
  StateWriter w;
  w.Begin("TESTSTAT", 1);
  w.Put(uint64_t{1} << 60);  // a count no buffer holds
  w.Put(uint8_t{2});         // not a boolean
  const std::vector<uint8_t> bytes = w.bytes();
  {
    StateReader r(bytes.data(), bytes.size());
    EXPECT_THROW(r.Begin("OTHERKND", 1), StateError);
  }
  {
    StateReader r(bytes.data(), bytes.size());
    try {
      r.Begin("TESTSTAT", 2);
      FAIL() << "another version was read";
    } catch (const StateError& e) {
      EXPECT_NE(std::string(e.what()).find("version 1, this program reads version 2"),
                std::string::npos)
          << e.what();
    }
  }
  StateReader r(bytes.data(), bytes.size());
  r.Begin("TESTSTAT", 1);
  try {
    r.Count(8, "nodes");
    FAIL() << "a count of 2^60 was accepted";
  } catch (const StateError& e) {
    EXPECT_NE(std::string(e.what()).find("at byte 16: nodes: a count of"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(r.GetBool("flag"), StateError);
  // Truncated: every read past the end is refused.
  StateReader t(bytes.data(), 10);
  EXPECT_THROW(t.Begin("TESTSTAT", 1), StateError);
  StateReader u(bytes.data(), bytes.size());
  u.Begin("TESTSTAT", 1);
  EXPECT_THROW(u.End("test state"), StateError);  // bytes left over
}

}  // namespace
}  // namespace fl

#include "fusionloc/common/number_format.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <limits>

namespace fl {
namespace {

TEST(NumberFormat, ShortestTextThatReadsBackExactly) {
  EXPECT_EQ(FormatDouble(0.2), "0.2");
  EXPECT_EQ(FormatDouble(0.1 + 0.2), "0.30000000000000004");
  EXPECT_EQ(FormatDouble(1e-6), "1e-06");
  EXPECT_EQ(FormatDouble(3.0), "3.0");
  EXPECT_EQ(FormatDouble(-250.0), "-250.0");
  EXPECT_EQ(FormatDouble(std::numeric_limits<double>::infinity()), ".inf");
  EXPECT_EQ(FormatDouble(-std::numeric_limits<double>::infinity()), "-.inf");
  EXPECT_EQ(FormatDouble(std::nan("")), ".nan");
  for (double v : {0.2, 1.0 / 3.0, 6.02214076e23, 4.9e-324, 2.2250738585072014e-308, -0.35}) {
    EXPECT_EQ(std::strtod(FormatDouble(v).c_str(), nullptr), v) << FormatDouble(v);
  }
}

TEST(NumberFormat, FloatsPrintAsFloats) {
  EXPECT_EQ(FormatFloat(0.1f), "0.1");
  EXPECT_EQ(FormatFloat(2.0f), "2.0");
  EXPECT_EQ(std::strtof(FormatFloat(1.0f / 3.0f).c_str(), nullptr), 1.0f / 3.0f);
}

}  // namespace
}  // namespace fl

// config/udev/99-fusionloc.rules gives the Hokuyo's tty the /dev/hokuyo link and the
// fusionloc group (the file docs/HARDWARE.md tells users to install).
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <regex>
#include <string>
#include <vector>

#include "test_paths.hpp"

namespace {

// KEY=="value" / KEY+="value" / KEY="value" assignments of one rule line.
std::map<std::string, std::string> Keys(const std::string& line) {
  std::map<std::string, std::string> out;
  static const std::regex kv(R"re(([A-Z]+(\{[a-zA-Z_]+\})?)\s*(==|\+=|=)\s*"([^"]*)")re");
  for (std::sregex_iterator it(line.begin(), line.end(), kv), end; it != end; ++it) {
    out[(*it)[1].str() + (*it)[3].str()] = (*it)[4].str();
  }
  return out;
}

TEST(UdevRules, HokuyoTtyGetsTheLinkAndTheGroup) {
  std::ifstream in(fl::test::SourceDir() + "/config/udev/99-fusionloc.rules");
  ASSERT_TRUE(in.good());
  std::string line;
  int tty_rules = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    // Every rule line is made of KEY op "value" pairs separated by commas.
    const std::string stripped = std::regex_replace(
        line, std::regex(R"re(([A-Z]+(\{[a-zA-Z_]+\})?)\s*(==|\+=|=)\s*"([^"]*)"\s*(,\s*)?)re"),
        "");
    EXPECT_EQ(stripped, "") << "not KEY==\"value\", ...: " << line;
    const auto k = Keys(line);
    if (k.count("SUBSYSTEM==") && k.at("SUBSYSTEM==") == "tty" && k.count("ATTRS{idVendor}==") &&
        k.at("ATTRS{idVendor}==") == "15d1") {
      ++tty_rules;
      EXPECT_EQ(k.at("ATTRS{idProduct}=="), "0000");
      EXPECT_EQ(k.at("SYMLINK+="), "hokuyo");
      EXPECT_EQ(k.at("GROUP="), "fusionloc");
      EXPECT_EQ(k.at("MODE="), "0660");
    }
  }
  EXPECT_EQ(tty_rules, 1);
}

}  // namespace

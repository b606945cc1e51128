// The bot_procman LCM types keep libbot2's layouts: their fingerprints are libbot2's (an LCM
// fingerprint covers field names, types and order, and ignores the package name), so that
// libbot2's sheriff, deputy and tools decode what ours send and the other way round.
#include "fusionloc/procman/bot_procman_types.hpp"

#include <gtest/gtest.h>

#include <cstdint>

namespace {

uint64_t Hash(int64_t h) { return static_cast<uint64_t>(h); }

TEST(BotProcmanTypes, FingerprintsAreLibbot2s) {
  EXPECT_EQ(Hash(bot_procman::orders2_t::getHash()), 0xef1277a9fdb17943ull);
  EXPECT_EQ(Hash(bot_procman::info2_t::getHash()), 0xd0cf2ed34edd8314ull);
  EXPECT_EQ(Hash(bot_procman::printf_t::getHash()), 0x0abac44d8e3a7badull);
  EXPECT_EQ(Hash(bot_procman::discovery_t::getHash()), 0x1116e1fff6333a71ull);
}

TEST(BotProcmanTypes, OrdersRoundTrip) {
  bot_procman::orders2_t o;
  o.utime = 123456789;
  o.host = "compute";
  o.sheriff_name = "sheriff";
  o.ncmds = 1;
  o.cmds.resize(1);
  o.cmds[0].cmd.exec_str = "sh -c 'exit 3'";
  o.cmds[0].cmd.command_name = "x";
  o.cmds[0].cmd.group = "g/sub";
  o.cmds[0].cmd.auto_respawn = true;
  o.cmds[0].cmd.stop_signal = 2;
  o.cmds[0].cmd.stop_time_allowed = 1.5f;
  o.cmds[0].cmd.num_options = 0;
  o.cmds[0].desired_runid = 7;
  o.cmds[0].force_quit = 0;
  o.cmds[0].sheriff_id = 42;
  o.num_options = 0;
  std::vector<uint8_t> buf(static_cast<size_t>(o.getEncodedSize()));
  ASSERT_EQ(o.encode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  bot_procman::orders2_t back;
  ASSERT_EQ(back.decode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  EXPECT_EQ(back.host, "compute");
  ASSERT_EQ(back.cmds.size(), 1u);
  EXPECT_EQ(back.cmds[0].cmd.exec_str, "sh -c 'exit 3'");
  EXPECT_EQ(back.cmds[0].cmd.group, "g/sub");
  EXPECT_EQ(back.cmds[0].desired_runid, 7);
  EXPECT_EQ(back.cmds[0].sheriff_id, 42);
  EXPECT_FLOAT_EQ(back.cmds[0].cmd.stop_time_allowed, 1.5f);
}

}  // namespace

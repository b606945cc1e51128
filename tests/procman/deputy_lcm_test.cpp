// DeputyNode over in-process LCM (memq://): the bot_procman conversions, and the order policy
// of a deputy with a key: signed orders act; unsigned, forged, other-key, stale and replayed
// orders are each refused, counted by reason, logged and told on PMD_PRINTF.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/procman/procman_lcm.hpp"
#include "test_paths.hpp"

namespace fl::procman {
namespace {

struct Rig {
  fl::test::TempDir dir;
  std::unique_ptr<LcmInterface> lcm = MakeLcm("memq://");
  Deputy deputy{Options(dir.path()), nullptr};
  std::unique_ptr<DeputyNode> node;
  std::string printed;
  bot_procman::info2_t last_info;
  int infos = 0;
  Rig(bool accept_unsigned, const Key* key) {
    DeputyNodeOptions o;
    o.accept_unsigned = accept_unsigned;
    node = std::make_unique<DeputyNode>(&deputy, lcm.get(), ChannelMap(), o);
    if (key) {
      node->EnableSignedOrders(
          std::make_unique<OrderVerifier>(std::vector<Key>{*key}, OrderVerifier::Options()),
          ChannelMap());
    }
    lcm->Subscribe<bot_procman::printf_t>(
        channels::kPmdPrintf,
        [this](const bot_procman::printf_t& m, const std::string&) { printed += m.text; });
    lcm->Subscribe<bot_procman::info2_t>(channels::kPmdInfo,
                                         [this](const bot_procman::info2_t& m, const std::string&) {
                                           last_info = m;
                                           ++infos;
                                         });
  }
  static DeputyOptions Options(const std::string& dir) {
    DeputyOptions o;
    o.name = "compute";
    o.log_dir = dir;
    return o;
  }
  void Spin(double s = 0.05) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(s);
    while (std::chrono::steady_clock::now() < end) {
      lcm->HandleSubscriptions(5);
      node->Poll();
    }
  }
  std::string Option(const std::string& key) {
    node->PublishStatus();
    lcm->HandleSubscriptions(5);
    for (size_t i = 0; i < last_info.option_names.size(); ++i) {
      if (last_info.option_names[i] == key) return last_info.option_values[i];
    }
    return "";
  }
};

bot_procman::orders2_t MakeOrders(const std::string& host, int32_t runid) {
  Orders o;
  o.utime_us = WallClockUs();
  o.host = host;
  o.sheriff_name = "test";
  CommandOrder c;
  c.spec.sheriff_id = 1;
  c.spec.name = "sleeper";
  c.spec.exec = "sleep 30";
  c.desired_runid = runid;
  o.cmds.push_back(c);
  return ToLcm(o);
}

std::vector<uint8_t> Encode(const bot_procman::orders2_t& o) {
  std::vector<uint8_t> b(static_cast<size_t>(o.getEncodedSize()));
  o.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

TEST(DeputyLcm, ConversionsKeepEveryField) {
  Orders o;
  o.utime_us = 42;
  o.host = "h";
  o.sheriff_name = "s";
  CommandOrder c;
  c.spec = {7, "n", "g/sub", "x 'y'", true, 15, 3.0};
  c.desired_runid = 9;
  c.force_quit = true;
  o.cmds.push_back(c);
  const Orders back = FromLcm(ToLcm(o));
  EXPECT_EQ(back.utime_us, 42);
  EXPECT_EQ(back.host, "h");
  ASSERT_EQ(back.cmds.size(), 1u);
  EXPECT_TRUE(back.cmds[0].spec == c.spec);
  EXPECT_EQ(back.cmds[0].desired_runid, 9);
  EXPECT_TRUE(back.cmds[0].force_quit);

  HostStatus h;
  h.host = "h";
  h.cpu_load = 0.5;
  h.mem_total_bytes = 100;
  CommandStatus s;
  s.spec = c.spec;
  s.state = CommandState::kRespawnWait;
  s.pid = 0;
  s.actual_runid = 9;
  s.exit_status = 3 << 8;
  s.exited = true;
  s.starts = 4;
  s.respawns = 3;
  s.peak_rss_bytes = 1 << 20;
  s.cpu_time_s = 1.5;
  s.error = "e";
  h.cmds.push_back(s);
  h.options["security"] = "x";
  const HostStatus hb = FromLcm(ToLcm(h));
  ASSERT_EQ(hb.cmds.size(), 1u);
  EXPECT_EQ(hb.cmds[0].state, CommandState::kRespawnWait);
  EXPECT_EQ(hb.cmds[0].exit_status, 3 << 8);
  EXPECT_TRUE(hb.cmds[0].exited);
  EXPECT_EQ(hb.cmds[0].starts, 4);
  EXPECT_EQ(hb.cmds[0].respawns, 3);
  EXPECT_EQ(hb.cmds[0].peak_rss_bytes, 1 << 20);
  EXPECT_DOUBLE_EQ(hb.cmds[0].cpu_time_s, 1.5);
  EXPECT_EQ(hb.cmds[0].error, "e");
  EXPECT_EQ(hb.options.at("security"), "x");
  EXPECT_FLOAT_EQ(static_cast<float>(hb.cpu_load), 0.5f);
}

TEST(DeputyLcm, InsecureDeputyActsOnPlainOrdersForItsHostOnly) {
  Rig rig(true, nullptr);
  rig.lcm->Publish(channels::kPmdOrders, MakeOrders("sensors", 1));
  rig.Spin();
  EXPECT_TRUE(rig.deputy.Commands().empty());
  rig.lcm->Publish(channels::kPmdOrders, MakeOrders("compute", 1));
  rig.Spin();
  ASSERT_EQ(rig.deputy.Commands().size(), 1u);
  EXPECT_GT(rig.deputy.Commands()[0].pid, 0);
  EXPECT_EQ(rig.node->refused().other_host, 1);
  EXPECT_GE(rig.infos, 1);  // status published at once
  EXPECT_NE(rig.Option("security").find("insecure"), std::string::npos);
}

TEST(DeputyLcm, KeyedDeputyRefusesUnsignedForgedOtherKeyStaleAndReplayedOrders) {
  const Key key = GenerateKey(), other = GenerateKey();
  Rig rig(false, &key);
  OrderSigner signer(key, "sheriff@test");
  OrderSigner stranger(other, "sheriff@elsewhere");
  const auto run = [&](const fusionloc::procman_signed_orders_t& e) {
    rig.lcm->Publish(channels::kPmdOrdersSigned, e);
    rig.Spin();
  };
  // Unsigned (a libbot2 sheriff): refused.
  rig.lcm->Publish(channels::kPmdOrders, MakeOrders("compute", 1));
  rig.Spin();
  // Signed with another key: refused (unknown key id).
  run(stranger.Sign(Encode(MakeOrders("compute", 1)), WallClockUs()));
  // Forged: right key id, altered orders (the MAC no longer matches).
  fusionloc::procman_signed_orders_t forged =
      signer.Sign(Encode(MakeOrders("compute", 1)), WallClockUs());
  forged.orders[forged.orders.size() / 2] ^= 0x01;
  run(forged);
  // Stale: signed two minutes ago.
  run(signer.Sign(Encode(MakeOrders("compute", 1)), WallClockUs() - 120'000'000));
  EXPECT_TRUE(rig.deputy.Commands().empty());
  EXPECT_EQ(rig.node->orders_applied(), 0);
  // A valid one acts ...
  const fusionloc::procman_signed_orders_t good =
      signer.Sign(Encode(MakeOrders("compute", 1)), WallClockUs());
  run(good);
  ASSERT_EQ(rig.deputy.Commands().size(), 1u);
  EXPECT_GT(rig.deputy.Commands()[0].pid, 0);
  EXPECT_EQ(rig.node->orders_applied(), 1);
  // ... once: played back, refused.
  run(good);
  EXPECT_EQ(rig.node->orders_applied(), 1);
  const auto& by = rig.node->refused().by_reason;
  EXPECT_EQ(by.at("unsigned"), 1);
  EXPECT_EQ(by.at("unknown_key"), 1);
  EXPECT_EQ(by.at("bad_mac"), 1);
  EXPECT_EQ(by.at("stale"), 1);
  EXPECT_EQ(by.at("replayed"), 1);
  EXPECT_EQ(rig.Option("refused_orders"), "5");
  EXPECT_EQ(rig.Option("refused_replayed"), "1");
  EXPECT_EQ(rig.Option("security"), "signed orders only");
  for (const char* kind : {"unsigned", "unknown_key", "bad_mac", "stale", "replayed"}) {
    EXPECT_NE(rig.printed.find(std::string("refused orders (") + kind + ")"), std::string::npos)
        << kind << "\n"
        << rig.printed;
  }
  // A signed order for another host: valid, not for this deputy.
  run(signer.Sign(Encode(MakeOrders("sensors", 2)), WallClockUs()));
  EXPECT_EQ(rig.node->refused().other_host, 1);
  EXPECT_EQ(rig.deputy.Commands()[0].actual_runid, 1);
}

}  // namespace
}  // namespace fl::procman

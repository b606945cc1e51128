#include "fusionloc/procman/order_auth.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>

#include "test_paths.hpp"

namespace fl::procman {
namespace {

using Verdict = OrderVerifier::Verdict;
using Envelope = fusionloc::procman_signed_orders_t;

constexpr int64_t kNow = 1'780'000'000'000'000;  // [us] some time in 2026

std::vector<uint8_t> SomeOrders() {
  // Stand-in for an LCM-encoded bot_procman.orders2_t: opaque bytes to the envelope.
  std::vector<uint8_t> o;
  for (int i = 0; i < 40; ++i) o.push_back(static_cast<uint8_t>(i * 37 + 11));
  return o;
}

OrderVerifier::Options Defaults() { return OrderVerifier::Options(); }

void WriteText(const std::string& path, const std::string& text, mode_t mode = 0600) {
  {
    std::ofstream out(path);
    out << text;
  }
  ASSERT_EQ(chmod(path.c_str(), mode), 0);
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The KeyError message of LoadKey(path), or "" if it loaded.
std::string LoadError(const std::string& path) {
  try {
    LoadKey(path);
  } catch (const KeyError& e) {
    return e.what();
  }
  return "";
}

const std::string kHex = "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff";

// ---- sign and verify ----

TEST(OrderAuth, SignedOrdersVerifyAndComeBackUnchanged) {
  const Key key = GenerateKey();
  OrderSigner signer(key, "sheriff@compute");
  OrderVerifier verifier({key}, Defaults());
  const Envelope e = signer.Sign(SomeOrders(), kNow);
  EXPECT_EQ(e.utime, kNow);
  EXPECT_EQ(e.sheriff_id, "sheriff@compute");
  EXPECT_EQ(e.key_id, key.id);
  EXPECT_EQ(e.orders_size, 40);
  std::vector<uint8_t> out;
  EXPECT_EQ(verifier.Verify(e, kNow + 200'000, &out), Verdict::kOk);
  EXPECT_EQ(out, SomeOrders());
  EXPECT_EQ(verifier.count(Verdict::kOk), 1);
  EXPECT_EQ(verifier.count(Verdict::kBadMac), 0);
  EXPECT_TRUE(verifier.last_detail().empty());
}

std::vector<uint8_t> Encode(const Envelope& e) {
  std::vector<uint8_t> wire(e.getEncodedSize());
  EXPECT_EQ(e.encode(wire.data(), 0, static_cast<int>(wire.size())), static_cast<int>(wire.size()));
  return wire;
}

// Returns the decoded size (negative on error) into *d. Out of line: inlined into a test body
// next to the encode, LCM 1.3.1's generated decode trips GCC 12's -Wmaybe-uninitialized on its
// msg_hash (a false positive from lcm_coretypes.h writing it through a uint64_t pointer).
[[gnu::noinline]] int Decode(const std::vector<uint8_t>& wire, Envelope* d) {
  return d->decode(wire.data(), 0, static_cast<int>(wire.size()));
}

TEST(OrderAuth, EnvelopeSurvivesTheLcmWireEncoding) {
  const Key key = GenerateKey();
  OrderSigner signer(key, "s");
  OrderVerifier verifier({key}, Defaults());
  const std::vector<uint8_t> wire = Encode(signer.Sign(SomeOrders(), kNow));
  Envelope d;
  ASSERT_EQ(Decode(wire, &d), static_cast<int>(wire.size()));
  std::vector<uint8_t> out;
  EXPECT_EQ(verifier.Verify(d, kNow, &out), Verdict::kOk);
  EXPECT_EQ(out, SomeOrders());
}

TEST(OrderAuth, EveryFlippedBitOfEveryFieldIsRefusedWithItsVerdict) {
  const Key key = GenerateKey();
  OrderSigner signer(key, "sheriff@compute");
  OrderVerifier verifier({key}, Defaults());
  const Envelope good = signer.Sign(SomeOrders(), kNow);
  const std::vector<uint8_t> sentinel = {0xde, 0xad};
  int64_t tried = 0;
  const auto expect = [&](const Envelope& bad, Verdict want, const std::string& what) {
    std::vector<uint8_t> out = sentinel;
    const Verdict got = verifier.Verify(bad, kNow, &out);
    ++tried;
    EXPECT_EQ(got, want) << what << ": got " << OrderVerifier::Name(got);
    EXPECT_EQ(out, sentinel) << what << ": refused orders must not be handed out";
  };
  for (std::size_t i = 0; i < good.orders.size(); ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      Envelope bad = good;
      bad.orders[i] ^= static_cast<uint8_t>(1u << bit);
      expect(bad, Verdict::kBadMac, "orders byte " + std::to_string(i));
    }
  }
  for (std::size_t i = 0; i < good.sheriff_id.size(); ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      Envelope bad = good;
      bad.sheriff_id[i] = static_cast<char>(bad.sheriff_id[i] ^ (1 << bit));
      expect(bad, Verdict::kBadMac, "sheriff_id byte " + std::to_string(i));
    }
  }
  for (std::size_t i = 0; i < good.key_id.size(); ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      Envelope bad = good;
      bad.key_id[i] = static_cast<char>(bad.key_id[i] ^ (1 << bit));
      expect(bad, Verdict::kUnknownKey, "key_id byte " + std::to_string(i));
    }
  }
  for (int bit = 0; bit < 64; ++bit) {
    Envelope bad = good;
    bad.utime = static_cast<int64_t>(static_cast<uint64_t>(good.utime) ^ (uint64_t{1} << bit));
    expect(bad, Verdict::kBadMac, "utime bit " + std::to_string(bit));
    bad = good;
    bad.counter = static_cast<int64_t>(static_cast<uint64_t>(good.counter) ^ (uint64_t{1} << bit));
    expect(bad, Verdict::kBadMac, "counter bit " + std::to_string(bit));
  }
  for (std::size_t i = 0; i < kMacBytes; ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      Envelope bad = good;
      bad.mac[i] ^= static_cast<uint8_t>(1u << bit);
      expect(bad, Verdict::kBadMac, "mac byte " + std::to_string(i));
    }
  }
  // Orders cut short, extended, or disagreeing with orders_size.
  Envelope bad = good;
  bad.orders.pop_back();
  bad.orders_size = static_cast<int32_t>(bad.orders.size());
  expect(bad, Verdict::kBadMac, "orders truncated");
  bad = good;
  bad.orders.push_back(0);
  bad.orders_size = static_cast<int32_t>(bad.orders.size());
  expect(bad, Verdict::kBadMac, "orders extended");
  bad = good;
  bad.orders_size += 1;
  expect(bad, Verdict::kMalformed, "orders_size off by one");
  bad = good;
  bad.orders_size = -1;
  expect(bad, Verdict::kMalformed, "negative orders_size");
  bad = good;
  bad.sheriff_id.clear();
  expect(bad, Verdict::kMalformed, "empty sheriff_id");

  const int64_t bits = 8 * static_cast<int64_t>(good.orders.size() + good.sheriff_id.size() +
                                                good.key_id.size() + kMacBytes) +
                       2 * 64;
  EXPECT_EQ(tried, bits + 5);
  EXPECT_EQ(verifier.count(Verdict::kOk), 0);
  EXPECT_EQ(verifier.count(Verdict::kUnknownKey), 8 * static_cast<int64_t>(good.key_id.size()));
  EXPECT_EQ(verifier.count(Verdict::kMalformed), 3);
  // None of the forgeries moved anything: the genuine envelope is still accepted, once.
  EXPECT_EQ(verifier.Verify(good, kNow, nullptr), Verdict::kOk);
}

TEST(OrderAuth, AnotherKeyIsAnUnknownIdAndAForgedIdIsABadMac) {
  const Key ours = GenerateKey();
  const Key theirs = GenerateKey();
  ASSERT_NE(ours.id, theirs.id);
  OrderVerifier verifier({ours}, Defaults());
  OrderSigner intruder(theirs, "sheriff@compute");
  Envelope e = intruder.Sign(SomeOrders(), kNow);
  EXPECT_EQ(verifier.Verify(e, kNow, nullptr), Verdict::kUnknownKey);
  EXPECT_NE(verifier.last_detail().find(theirs.id), std::string::npos) << verifier.last_detail();
  // The intruder claims our key's id and MACs with its own key.
  e.key_id = ours.id;
  const auto mac = ComputeMac(Key{ours.id, theirs.bytes}, e);
  std::copy(mac.begin(), mac.end(), e.mac);
  EXPECT_EQ(verifier.Verify(e, kNow, nullptr), Verdict::kBadMac);
  EXPECT_EQ(verifier.count(Verdict::kUnknownKey), 1);
  EXPECT_EQ(verifier.count(Verdict::kBadMac), 1);

  // A deputy holding both keys obeys both sheriffs.
  OrderVerifier both({ours, theirs}, Defaults());
  OrderSigner friendly(ours, "sheriff@sensors");
  EXPECT_EQ(both.Verify(intruder.Sign(SomeOrders(), kNow + 1), kNow, nullptr), Verdict::kOk);
  EXPECT_EQ(both.Verify(friendly.Sign(SomeOrders(), kNow + 2), kNow, nullptr), Verdict::kOk);
}

TEST(OrderAuth, OrdersOutsideTheClockWindowAreStale) {
  const Key key = GenerateKey();
  OrderVerifier::Options opt;
  opt.max_age_s = 60.0;
  opt.max_future_s = 5.0;
  {
    OrderSigner signer(key, "s");
    OrderVerifier verifier({key}, opt);
    const Envelope e = signer.Sign(SomeOrders(), kNow);
    EXPECT_EQ(verifier.Verify(e, kNow + 60'500'000, nullptr), Verdict::kStale);
    EXPECT_NE(verifier.last_detail().find("60.5 s old"), std::string::npos)
        << verifier.last_detail();
    EXPECT_EQ(verifier.Verify(e, kNow - 5'500'000, nullptr), Verdict::kStale);
    EXPECT_NE(verifier.last_detail().find("in the future"), std::string::npos)
        << verifier.last_detail();
    EXPECT_EQ(verifier.count(Verdict::kStale), 2);
    // Inside the window it is accepted (the stale refusals did not use up its counter).
    EXPECT_EQ(verifier.Verify(e, kNow + 59'000'000, nullptr), Verdict::kOk);
  }
  {
    OrderSigner signer(key, "s");
    OrderVerifier verifier({key}, opt);
    EXPECT_EQ(verifier.Verify(signer.Sign(SomeOrders(), kNow), kNow - 4'000'000, nullptr),
              Verdict::kOk);
  }
}

TEST(OrderAuth, ReplayedOrALowerCounterIsRefusedPerSheriff) {
  const Key key = GenerateKey();
  OrderSigner a(key, "sheriff-a");
  OrderSigner b(key, "sheriff-b");
  OrderVerifier verifier({key}, Defaults());
  const Envelope a1 = a.Sign(SomeOrders(), kNow);
  const Envelope a2 = a.Sign(SomeOrders(), kNow);
  ASSERT_GT(a2.counter, a1.counter);
  EXPECT_EQ(verifier.Verify(a2, kNow, nullptr), Verdict::kOk);
  EXPECT_EQ(verifier.Verify(a2, kNow, nullptr), Verdict::kReplayed);  // the same envelope
  EXPECT_EQ(verifier.Verify(a1, kNow, nullptr), Verdict::kReplayed);  // a lower counter
  EXPECT_NE(verifier.last_detail().find(std::to_string(a2.counter)), std::string::npos)
      << verifier.last_detail();
  // Another sheriff has its own counter, even when it is lower than a's.
  const Envelope b1 = b.Sign(SomeOrders(), kNow - 1000);
  ASSERT_LT(b1.counter, a2.counter);
  EXPECT_EQ(verifier.Verify(b1, kNow, nullptr), Verdict::kOk);
  EXPECT_EQ(verifier.Verify(a.Sign(SomeOrders(), kNow), kNow, nullptr), Verdict::kOk);
  EXPECT_EQ(verifier.count(Verdict::kReplayed), 2);
  EXPECT_EQ(verifier.count(Verdict::kOk), 3);
}

TEST(OrderAuth, AForgedOrStaleEnvelopeNeverMovesTheCounter) {
  const Key key = GenerateKey();
  OrderSigner signer(key, "s");
  OrderVerifier verifier({key}, Defaults());
  const Envelope genuine = signer.Sign(SomeOrders(), kNow);
  // A forgery with a far higher counter: if it moved the counter, genuine would be a replay.
  Envelope forged = genuine;
  forged.counter += 1'000'000'000;
  EXPECT_EQ(verifier.Verify(forged, kNow, nullptr), Verdict::kBadMac);
  // Authentic but from a sheriff whose clock runs 100 s ahead: stale, and no counter move.
  OrderSigner ahead(key, "s");
  EXPECT_EQ(verifier.Verify(ahead.Sign(SomeOrders(), kNow + 100'000'000), kNow, nullptr),
            Verdict::kStale);
  EXPECT_EQ(verifier.Verify(genuine, kNow, nullptr), Verdict::kOk);
}

TEST(OrderAuth, SignerCountersOnlyGoUpAlsoAcrossARestart) {
  const Key key = GenerateKey();
  int64_t last = 0;
  {
    OrderSigner signer(key, "s");
    for (int i = 0; i < 100; ++i) {  // many orders in one microsecond, then the clock steps back
      const int64_t now = i < 50 ? kNow : kNow - 10'000'000;
      const Envelope e = signer.Sign({}, now);
      EXPECT_GT(e.counter, last);
      EXPECT_EQ(e.utime, now);
      last = e.counter;
    }
    EXPECT_EQ(signer.last_counter(), last);
  }
  // The restarted sheriff has no state but a later clock: its counters are above the old ones.
  OrderSigner restarted(key, "s");
  EXPECT_GT(restarted.Sign({}, kNow + 1'000'000).counter, last);
}

// The canonical bytes are length-prefixed: moving a byte from one field to the next changes
// the MAC.
TEST(OrderAuth, CanonicalEncodingHasNoAmbiguity) {
  const Key key = GenerateKey();
  Envelope x;
  x.utime = kNow;
  x.counter = 7;
  x.sheriff_id = "ab";
  x.key_id = "c";
  Envelope y = x;
  y.sheriff_id = "a";
  y.key_id = "bc";
  EXPECT_NE(ComputeMac(key, x), ComputeMac(key, y));
  // key_id / orders boundary (the counter sits between them; make it match bytes).
  Envelope p = x;
  p.key_id = "k";
  p.orders = {'o', 'r'};
  p.orders_size = 2;
  Envelope q = x;
  q.key_id = "ko";
  q.orders = {'r'};
  q.orders_size = 1;
  EXPECT_NE(ComputeMac(key, p), ComputeMac(key, q));
  // The MAC is the one Sign writes, and it depends on the key.
  OrderSigner signer(key, "s");
  const Envelope e = signer.Sign(SomeOrders(), kNow);
  const auto mac = ComputeMac(key, e);
  EXPECT_TRUE(std::equal(mac.begin(), mac.end(), e.mac));
  EXPECT_NE(ComputeMac(GenerateKey(), e), mac);
}

TEST(OrderAuth, HostileIdsAreEscapedInTheLogLine) {
  const Key key = GenerateKey();
  OrderVerifier verifier({key}, Defaults());
  OrderSigner signer(key, "s");
  Envelope e = signer.Sign(SomeOrders(), kNow);
  e.sheriff_id = "evil\n[INFO] all good";
  EXPECT_EQ(verifier.Verify(e, kNow, nullptr), Verdict::kBadMac);
  EXPECT_EQ(verifier.last_detail().find('\n'), std::string::npos) << verifier.last_detail();
  EXPECT_NE(verifier.last_detail().find("evil\\x0a"), std::string::npos) << verifier.last_detail();
  EXPECT_EQ(verifier.last_detail().rfind("bad MAC: ", 0), 0u) << verifier.last_detail();
}

TEST(OrderAuth, ConstructorsRefuseBadArguments) {
  const Key key = GenerateKey();
  EXPECT_THROW(OrderSigner(key, ""), std::invalid_argument);
  Key renamed = key;
  renamed.id = "0000000000000000";
  EXPECT_THROW(OrderSigner(renamed, "s"), std::invalid_argument);
  EXPECT_THROW(OrderVerifier({renamed}, Defaults()), std::invalid_argument);
  EXPECT_THROW(OrderVerifier({}, Defaults()), std::invalid_argument);
  OrderVerifier::Options opt;
  opt.max_age_s = 0.0;
  EXPECT_FALSE(opt.Validate().ok());
  EXPECT_NE(opt.Validate().message().find("max_age_s"), std::string::npos);
  EXPECT_THROW(OrderVerifier({key}, opt), std::invalid_argument);
  opt = OrderVerifier::Options();
  opt.max_future_s = -1.0;
  EXPECT_NE(opt.Validate().message().find("max_future_s"), std::string::npos);
  opt.max_future_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(opt.Validate().ok());
  EXPECT_TRUE(OrderVerifier::Options().Validate().ok());
  EXPECT_STREQ(OrderVerifier::Name(Verdict::kReplayed), "replayed");
  EXPECT_STREQ(OrderVerifier::Name(Verdict::kUnknownKey), "unknown key id");
}

// ---- keys and key files ----

TEST(OrderAuthKeys, KeyIdIsAStableNameThatIsNotTheKey) {
  const Key a = GenerateKey();
  const Key b = GenerateKey();
  EXPECT_EQ(a.id.size(), 16u);
  EXPECT_EQ(a.id.find_first_not_of("0123456789abcdef"), std::string::npos) << a.id;
  EXPECT_EQ(KeyId(a.bytes), a.id);
  EXPECT_NE(a.id, b.id);
  EXPECT_NE(a.bytes, b.bytes);
  std::array<unsigned char, kKeyBytes> fixed{};
  for (std::size_t i = 0; i < fixed.size(); ++i) fixed[i] = static_cast<unsigned char>(i);
  EXPECT_NE(KeyId(fixed), "0001020304050607");  // not a prefix of the key
  EXPECT_EQ(KeyId(fixed), KeyId(fixed));
}

TEST(OrderAuthKeys, WriteNewKeyMakesAPrivateKeyThatLoads) {
  fl::test::TempDir dir;
  const std::string path = dir.file("etc/fusionloc/procman.key");
  WriteNewKey(path);
  struct stat st;
  ASSERT_EQ(stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0600u);
  ASSERT_EQ(stat(dir.file("etc/fusionloc").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0700u);
  ASSERT_EQ(stat(dir.file("etc").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0700u);
  const Key key = LoadKey(path);
  EXPECT_EQ(key.id, KeyId(key.bytes));
  EXPECT_NE(ReadText(path).find(key.id), std::string::npos) << "the comment names the id";
  // Two new keys differ.
  WriteNewKey(dir.file("other.key"));
  EXPECT_NE(LoadKey(dir.file("other.key")).bytes, key.bytes);
  // A key of a documented text file loads as its hex says.
  WriteText(dir.file("hand.key"), "# made by hand\n\n  " + kHex + "  \r\n\n");
  const Key hand = LoadKey(dir.file("hand.key"));
  EXPECT_EQ(hand.bytes[1], 0x11);
  EXPECT_EQ(hand.bytes[31], 0xff);
}

TEST(OrderAuthKeys, WriteNewKeyRefusesToOverwrite) {
  fl::test::TempDir dir;
  const std::string path = dir.file("procman.key");
  WriteNewKey(path);
  const std::string before = ReadText(path);
  try {
    WriteNewKey(path);
    ADD_FAILURE() << "overwrote an existing key";
  } catch (const KeyError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("already exists"), std::string::npos) << e.what();
  }
  EXPECT_EQ(ReadText(path), before);
  // Nor through a symbolic link to somewhere else.
  const std::string link = dir.file("link.key");
  ASSERT_EQ(symlink(dir.file("elsewhere").c_str(), link.c_str()), 0);
  EXPECT_THROW(WriteNewKey(link), KeyError);
  EXPECT_FALSE(std::filesystem::exists(dir.file("elsewhere")));
}

// Tests run as root in CI, where access() says yes to everything: the mode bits are checked.
TEST(OrderAuthKeys, AKeyOthersCanReadIsRefusedWithTheChmodFix) {
  fl::test::TempDir dir;
  const std::string path = dir.file("procman.key");
  for (const mode_t bad : {0644, 0640, 0604, 0660, 0606, 0700, 0500, 0200}) {
    WriteText(path, kHex + "\n", bad);
    const std::string err = LoadError(path);
    EXPECT_NE(err.find("chmod 600 " + path), std::string::npos) << std::oct << bad << ": " << err;
  }
  WriteText(path, kHex + "\n", 0644);
  EXPECT_NE(LoadError(path).find("mode 0644"), std::string::npos) << LoadError(path);
  for (const mode_t good : {0600, 0400}) {
    WriteText(path, kHex + "\n", good);
    EXPECT_EQ(LoadError(path), "") << std::oct << good;
  }
}

TEST(OrderAuthKeys, MissingOrNotARegularFileIsRefusedWithTheFix) {
  fl::test::TempDir dir;
  const std::string missing = dir.file("nope.key");
  std::string err = LoadError(missing);
  EXPECT_NE(err.find(missing), std::string::npos) << err;
  EXPECT_NE(err.find("--new-key " + missing), std::string::npos) << err;
  err = LoadError(dir.path());
  EXPECT_NE(err.find(dir.path() + " is a folder"), std::string::npos) << err;
  const std::string fifo = dir.file("fifo.key");
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  err = LoadError(fifo);  // must not block waiting for a writer
  EXPECT_NE(err.find("not a regular file"), std::string::npos) << err;
}

TEST(OrderAuthKeys, AKeyOwnedByAnotherUserIsRefused) {
  if (geteuid() != 0) GTEST_SKIP() << "needs root to give a file to another user";
  fl::test::TempDir dir;
  const std::string path = dir.file("procman.key");
  WriteText(path, kHex + "\n");
  ASSERT_EQ(chown(path.c_str(), 4242, 4242), 0);
  const std::string err = LoadError(path);
  EXPECT_NE(err.find("uid 4242"), std::string::npos) << err;
  EXPECT_NE(err.find("chown"), std::string::npos) << err;
}

TEST(OrderAuthKeys, MalformedKeyFilesNameTheFileAndLineButNotTheKey) {
  fl::test::TempDir dir;
  const std::string path = dir.file("procman.key");
  struct Case {
    std::string text;
    std::string want;
  };
  const std::vector<Case> cases = {
      {"# comment\nabc\n", path + ":2: expected the key as 64 hex digits, found 3"},
      {"# comment\n" + kHex.substr(0, 10) + "zz" + kHex.substr(12) + "\n",
       path + ":2: not a hex digit at column 11"},
      {"\n" + kHex + "0\n", path + ":2: expected the key as 64 hex digits, found 65"},
      {kHex + "\n# fine\n" + kHex + "\n", path + ":3: unexpected text after the key on line 1"},
      {"", path + ": no key in the file"},
      {"# only a comment\n\n", path + ": no key in the file"},
      {std::string(64, '0') + "\n", path + ":1: the key is all zeros"},
  };
  for (const Case& c : cases) {
    WriteText(path, c.text);
    const std::string err = LoadError(path);
    EXPECT_NE(err.find(c.want), std::string::npos) << "file:\n" << c.text << "error: " << err;
    EXPECT_NE(err.find("--new-key"), std::string::npos) << err;
    EXPECT_EQ(err.find(kHex.substr(12, 20)), std::string::npos) << "echoes the key: " << err;
  }
}

class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    if (value != nullptr) {
      setenv(name, value, 1);
    } else {
      unsetenv(name);
    }
  }
  ~ScopedEnv() {
    if (old_) {
      setenv(name_, old_->c_str(), 1);
    } else {
      unsetenv(name_);
    }
  }

 private:
  const char* name_;
  std::optional<std::string> old_;
};

TEST(OrderAuthKeys, DefaultKeyPathFollowsTheDocumentedRule) {
  {
    ScopedEnv env("FUSIONLOC_PROCMAN_KEY", "/somewhere/my.key");
    EXPECT_EQ(DefaultKeyPath(), "/somewhere/my.key");
  }
  ScopedEnv no_env("FUSIONLOC_PROCMAN_KEY", nullptr);
  ScopedEnv xdg("XDG_CONFIG_HOME", "/xdg");
  ScopedEnv home("HOME", "/home/robot");
  if (geteuid() == 0) {
    EXPECT_EQ(DefaultKeyPath(), "/etc/fusionloc/procman.key");
  } else {
    EXPECT_EQ(DefaultKeyPath(), "/xdg/fusionloc/procman.key");
    ScopedEnv relative("XDG_CONFIG_HOME", "relative");  // not absolute: ignored (XDG spec)
    EXPECT_EQ(DefaultKeyPath(), "/home/robot/.config/fusionloc/procman.key");
  }
}

}  // namespace
}  // namespace fl::procman

// Signed procman orders (fl-procman-deputy's PMD_ORDERS2_SIGNED): the envelope's decode, the
// verifier, and the orders inside. Mode byte 0: the rest is an envelope from the network
// (forged: must never be accepted, since the fuzzer does not know the key). Mode 1: the rest
// is an orders2_t payload that the harness signs, so the decode of what a valid envelope
// carries is fuzzed too; the envelope must then be accepted once and refused as a replay.
#include <array>
#include <vector>

#include "../fuzz_entry.hpp"
#include "bot_procman/orders2_t.hpp"
#include "fusionloc/procman/order_auth.hpp"
#include "fusionloc/procman/procman_lcm.hpp"
#include "fusionloc/procman_signed_orders_t.hpp"

namespace pm = fl::procman;

namespace {
pm::Key FuzzKey() {
  pm::Key key;
  for (size_t i = 0; i < key.bytes.size(); ++i) key.bytes[i] = static_cast<unsigned char>(7 * i + 1);
  key.id = pm::KeyId(key.bytes);
  return key;
}
constexpr int64_t kNowUs = 1700000000000000;

void UseOrders(const std::vector<uint8_t>& encoded) {
  bot_procman::orders2_t orders;
  if (orders.decode(encoded.data(), 0, static_cast<int>(encoded.size())) !=
      static_cast<int>(encoded.size())) {
    return;
  }
  const pm::Orders o = pm::FromLcm(orders);
  FL_FUZZ_CHECK(o.cmds.size() <= encoded.size());
}
}  // namespace

int Fuzz_procman_orders(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  const uint8_t mode = in.Byte() % 2;
  const std::string_view rest = in.Rest();
  pm::OrderVerifier verifier({FuzzKey()}, pm::OrderVerifier::Options{});
  std::vector<uint8_t> encoded;
  if (mode == 0) {
    fusionloc::procman_signed_orders_t env;
    if (env.decode(rest.data(), 0, static_cast<int>(rest.size())) != static_cast<int>(rest.size())) {
      return 0;
    }
    const auto v = verifier.Verify(env, kNowUs, &encoded);
    FL_FUZZ_CHECK(v != pm::OrderVerifier::Verdict::kOk);  // a forgery
    return 0;
  }
  pm::OrderSigner signer(FuzzKey(), "fuzz@host");
  const fusionloc::procman_signed_orders_t signed_env =
      signer.Sign(std::vector<uint8_t>(rest.begin(), rest.end()), kNowUs);
  std::vector<uint8_t> wire(static_cast<size_t>(signed_env.getEncodedSize()));
  signed_env.encode(wire.data(), 0, static_cast<int>(wire.size()));
  fusionloc::procman_signed_orders_t env;
  FL_FUZZ_CHECK(env.decode(wire.data(), 0, static_cast<int>(wire.size())) ==
                static_cast<int>(wire.size()));
  FL_FUZZ_CHECK(verifier.Verify(env, kNowUs, &encoded) == pm::OrderVerifier::Verdict::kOk);
  FL_FUZZ_CHECK(encoded.size() == rest.size());
  std::vector<uint8_t> again;
  FL_FUZZ_CHECK(verifier.Verify(env, kNowUs, &again) == pm::OrderVerifier::Verdict::kReplayed);
  UseOrders(encoded);
  return 0;
}

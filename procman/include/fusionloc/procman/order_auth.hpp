// Signed procman orders: a shared secret key, a sheriff that signs each bot_procman.orders2_t
// it sends, and a deputy that acts only on orders carrying a valid MAC, a time inside its
// window and a counter above the last one it accepted from that sheriff. libbot2's procman has
// no authentication (anyone on the LCM network can make a deputy run anything); this closes
// that. Threat model, key placement and limits: docs/PROCMAN_SECURITY.md.
//
// The MAC is libsodium's crypto_auth (HMAC-SHA512-256); nothing here hand-rolls crypto. It
// covers this byte string, every length a 4-byte big-endian prefix, every integer 8 bytes
// big-endian:
//   len("fusionloc-procman-orders-v1") "fusionloc-procman-orders-v1"
//   utime  len(sheriff_id) sheriff_id  len(key_id) key_id  counter  len(orders) orders
// so no two different envelopes share one (sheriff_id "ab" + key_id "c" differs from "a"+"bc").
//
// Key file (text, mode 0600 or 0400, owned by the user reading it or by root):
//   # any number of comment lines starting with '#', and blank lines
//   <64 hex digits: the 32-byte key>
// Made by WriteNewKey (fl-procman-sheriff --new-key FILE); the same file goes on every host.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/procman_signed_orders_t.hpp"

namespace fl::procman {

constexpr std::size_t kKeyBytes = 32;  // crypto_auth_KEYBYTES (checked in order_auth.cpp)
constexpr std::size_t kMacBytes = 32;  // crypto_auth_BYTES, the envelope's mac[32]

// A key file that is missing, malformed, not a regular file or open to others; the message
// names the file and the fix. Also thrown by WriteNewKey and DefaultKeyPath.
class KeyError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Key {
  std::string id;  // KeyId(bytes): 16 hex digits, safe to print and to put on the wire
  std::array<unsigned char, kKeyBytes> bytes{};
};

// The public name of a key: the first 8 bytes of BLAKE2b (crypto_generichash) keyed with the
// key over "fusionloc-procman-key-id-v1", in lower-case hex. Reveals nothing about the key.
std::string KeyId(const std::array<unsigned char, kKeyBytes>& bytes);

// The MAC of an envelope under `key`: crypto_auth over the canonical bytes of every field but
// mac (file comment). What Sign writes; Verify checks it with crypto_auth_verify.
std::array<uint8_t, kMacBytes> ComputeMac(const Key& key,
                                          const fusionloc::procman_signed_orders_t& envelope);

// A fresh random key in memory (randombytes_buf), e.g. for tests.
Key GenerateKey();

// Reads a key file (format above). Throws KeyError naming the file and the fix when it is
// missing, unreadable, not a regular file, owned by another user (other than root), has a
// mode other than 0600 or 0400 (e.g. group/others may read it: "chmod 600 FILE"), or is
// malformed (naming the line). Never echoes the key.
Key LoadKey(const std::string& path);

// Writes a new random key to `path`: missing parent folders are created with mode 0700, the
// file is created exclusively (O_EXCL) with mode 0600. Refuses (KeyError) to overwrite an
// existing file, since every deputy holding the old key would stop obeying.
void WriteNewKey(const std::string& path);

// Where a key is looked for when none is given:
//   1. $FUSIONLOC_PROCMAN_KEY, if set and not empty;
//   2. as root (effective uid 0): /etc/fusionloc/procman.key;
//   3. otherwise $XDG_CONFIG_HOME/fusionloc/procman.key if $XDG_CONFIG_HOME is an absolute
//      path, else $HOME/.config/fusionloc/procman.key (home from the password database when
//      $HOME is unset).
// Throws KeyError only when no home folder can be found for rule 3.
std::string DefaultKeyPath();
// The default key file if it exists, else "" (a sheriff or fl-procman-ctl without --key signs
// only when there is one).
std::string ExistingDefaultKeyPath();

// Signs orders for one sheriff. The counter is max(last + 1, now_us): strictly increasing,
// and after a restart it starts from the clock again, above anything issued before (as long
// as the sheriff's clock does not step back), with no state on disk.
class OrderSigner {
 public:
  // Throws std::invalid_argument if sheriff_id is empty or key.id != KeyId(key.bytes).
  OrderSigner(Key key, std::string sheriff_id);
  ~OrderSigner();  // wipes the key (sodium_memzero)
  OrderSigner(const OrderSigner&) = delete;
  OrderSigner& operator=(const OrderSigner&) = delete;

  // encoded_orders2: an LCM-encoded bot_procman.orders2_t. now_us: the sheriff's clock
  // [us since the epoch]. Throws std::invalid_argument if the orders exceed 2^31-1 bytes.
  fusionloc::procman_signed_orders_t Sign(const std::vector<uint8_t>& encoded_orders2,
                                          int64_t now_us);

  const std::string& sheriff_id() const { return sheriff_id_; }
  const std::string& key_id() const { return key_.id; }
  int64_t last_counter() const { return last_counter_; }

 private:
  Key key_;
  std::string sheriff_id_;
  int64_t last_counter_ = 0;
};

// Checks envelopes on a deputy. In this order: malformed, unknown key id, bad MAC, stale,
// replayed; only a valid MAC lets the time and counter be looked at, and only an accepted
// envelope (kOk) moves its sheriff's counter, so a forgery never changes what is accepted
// next. Not thread-safe: call Verify (and count) from one thread, or guard it.
//
// Not covered by design (docs/PROCMAN_SECURITY.md): the counters live in memory, so after a
// deputy restart an envelope recorded in the last max_age_s can be accepted once more.
class OrderVerifier {
 public:
  struct Options {
    // [s] an envelope whose utime is older than this (deputy's clock) is stale. libbot2
    // deputies ignore orders older than a minute; hosts' clocks must agree to well within it.
    double max_age_s = 60.0;
    // [s] an envelope whose utime is further ahead of the deputy's clock than this is stale
    // (a sheriff with a clock running ahead could otherwise pre-sign orders for later).
    double max_future_s = 5.0;

    template <class Archive>
    void Serialize(Archive* a) {
      a->Visit("max_age_s", &max_age_s);
      a->Visit("max_future_s", &max_future_s);
    }
    // max_age_s > 0 and max_future_s >= 0, both finite (the repo's Options convention).
    fl::Status Validate() const;
  };

  enum class Verdict { kOk, kMalformed, kUnknownKey, kBadMac, kStale, kReplayed };
  static constexpr int kNumVerdicts = 6;

  // Throws std::invalid_argument if keys is empty, a key's id is not KeyId(bytes), or the
  // options are invalid (Validate's message).
  OrderVerifier(std::vector<Key> keys, Options options);
  ~OrderVerifier();  // wipes the keys
  OrderVerifier(const OrderVerifier&) = delete;
  OrderVerifier& operator=(const OrderVerifier&) = delete;

  // now_us: the deputy's clock [us since the epoch]. On kOk copies the orders into
  // *encoded_orders2 (if not null); on any other verdict leaves it untouched.
  Verdict Verify(const fusionloc::procman_signed_orders_t& envelope, int64_t now_us,
                 std::vector<uint8_t>* encoded_orders2);

  // Envelopes given each verdict since construction.
  int64_t count(Verdict verdict) const;
  // One line on the last refusal, for the log, e.g. "stale: utime 75.3 s old (max_age_s
  // 60) from sheriff \"s@h\""; empty after kOk. Never contains key material.
  const std::string& last_detail() const { return last_detail_; }
  // "ok", "malformed", "unknown key id", "bad MAC", "stale", "replayed".
  static const char* Name(Verdict verdict);

 private:
  Verdict Refuse(Verdict verdict, std::string detail);

  std::vector<Key> keys_;
  Options options_;
  std::map<std::string, int64_t> last_counter_;  // per sheriff_id, of accepted envelopes
  std::array<int64_t, kNumVerdicts> counts_{};
  std::string last_detail_;
};

}  // namespace fl::procman

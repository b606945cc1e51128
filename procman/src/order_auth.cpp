#include "fusionloc/procman/order_auth.hpp"

#include <errno.h>
#include <fcntl.h>
#include <pwd.h>
#include <sodium.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string_view>
#include <utility>

namespace fl::procman {
namespace {

static_assert(kKeyBytes == crypto_auth_KEYBYTES, "Key::bytes must hold a crypto_auth key");
static_assert(kMacBytes == crypto_auth_BYTES,
              "procman_signed_orders_t.mac must be crypto_auth_BYTES");

constexpr char kMacDomain[] = "fusionloc-procman-orders-v1";
constexpr char kKeyIdDomain[] = "fusionloc-procman-key-id-v1";
constexpr std::size_t kKeyIdBytes = 8;               // shown as 16 hex digits
constexpr std::size_t kMaxKeyFileBytes = 64 * 1024;  // a key file is ~200 bytes

// sodium_init() once per process; C++ guarantees a thread-safe initialisation of the static.
void EnsureSodium() {
  static const int rc = sodium_init();
  if (rc < 0) throw std::runtime_error("libsodium could not be initialised (sodium_init failed)");
}

std::string Hex(const unsigned char* bytes, std::size_t n) {
  std::string hex(2 * n + 1, '\0');
  sodium_bin2hex(hex.data(), hex.size(), bytes, n);
  hex.pop_back();
  return hex;
}

// Attacker-chosen strings (sheriff and key ids from the network) made safe for one log line.
std::string Printable(const std::string& s) {
  constexpr std::size_t kMax = 64;
  std::string out = "\"";
  for (std::size_t i = 0; i < s.size() && i < kMax; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f && c != '"' && c != '\\') {
      out += static_cast<char>(c);
    } else {
      char esc[8];
      std::snprintf(esc, sizeof(esc), "\\x%02x", c);
      out += esc;
    }
  }
  out += "\"";
  if (s.size() > kMax) out += "... (" + std::to_string(s.size()) + " bytes)";
  return out;
}

void PutU32(std::vector<unsigned char>* b, uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8) b->push_back(static_cast<unsigned char>(v >> shift));
}
void PutI64(std::vector<unsigned char>* b, int64_t value) {
  const uint64_t v = static_cast<uint64_t>(value);
  for (int shift = 56; shift >= 0; shift -= 8) b->push_back(static_cast<unsigned char>(v >> shift));
}
void PutBytes(std::vector<unsigned char>* b, const void* data, std::size_t n) {
  PutU32(b, static_cast<uint32_t>(n));  // n < 2^31: LCM lengths are int32_t
  const auto* p = static_cast<const unsigned char*>(data);
  b->insert(b->end(), p, p + n);
}

// The byte string the MAC covers (order_auth.hpp). orders_size is implied by len(orders);
// Verify refuses an envelope where the two disagree before it gets here.
std::vector<unsigned char> CanonicalBytes(const fusionloc::procman_signed_orders_t& e) {
  std::vector<unsigned char> b;
  b.reserve(64 + e.sheriff_id.size() + e.key_id.size() + e.orders.size());
  PutBytes(&b, kMacDomain, sizeof(kMacDomain) - 1);
  PutI64(&b, e.utime);
  PutBytes(&b, e.sheriff_id.data(), e.sheriff_id.size());
  PutBytes(&b, e.key_id.data(), e.key_id.size());
  PutI64(&b, e.counter);
  PutBytes(&b, e.orders.data(), e.orders.size());
  return b;
}

void CheckKeyId(const Key& key, const char* who) {
  if (key.id != KeyId(key.bytes)) {
    throw std::invalid_argument(std::string(who) + ": key id " + Printable(key.id) +
                                " is not the id of its bytes; make keys with LoadKey or "
                                "GenerateKey");
  }
}

// Zeroes a buffer that held key material when it goes out of scope, also on a throw.
struct Wipe {
  void* data;
  std::size_t size;
  ~Wipe() { sodium_memzero(data, size); }
};

struct Fd {
  int fd;
  ~Fd() {
    if (fd >= 0) close(fd);
  }
};

std::string NewKeyHint(const std::string& path) {
  return "make one with `fl-procman-sheriff --new-key " + path +
         "` and copy it (mode 0600) to the sheriff and every deputy host";
}

std::string ModeString(mode_t mode) {
  char s[8];
  std::snprintf(s, sizeof(s), "%04o", static_cast<unsigned>(mode & 07777));
  return s;
}

bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r'; }

// Parses the key file text (order_auth.hpp); errors name file and line, never the content.
std::array<unsigned char, kKeyBytes> ParseKeyText(std::string_view text, const std::string& path) {
  const std::string regen = "; remove it and make a new one with `fl-procman-sheriff --new-key " +
                            path + "` (then copy it to every host)";
  std::array<unsigned char, kKeyBytes> bytes{};
  int key_line = 0;
  int line_no = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    const std::size_t line_start = pos;
    std::size_t b = pos, e = end;
    pos = end + 1;
    ++line_no;
    while (b < e && IsBlank(text[b])) ++b;
    while (e > b && IsBlank(text[e - 1])) --e;
    if (b == e || text[b] == '#') continue;
    const std::string where = path + ":" + std::to_string(line_no) + ": ";
    if (key_line != 0) {
      throw KeyError(where + "unexpected text after the key on line " + std::to_string(key_line) +
                     " (a key file holds '#' comments and one line of " +
                     std::to_string(2 * kKeyBytes) + " hex digits)" + regen);
    }
    const std::size_t n = e - b;
    if (n != 2 * kKeyBytes) {
      throw KeyError(where + "expected the key as " + std::to_string(2 * kKeyBytes) +
                     " hex digits, found " + std::to_string(n) + " characters" + regen);
    }
    for (std::size_t i = b; i < e; ++i) {
      if (!std::isxdigit(static_cast<unsigned char>(text[i]))) {
        throw KeyError(where + "not a hex digit at column " + std::to_string(i - line_start + 1) +
                       regen);
      }
    }
    std::size_t bin_len = 0;
    if (sodium_hex2bin(bytes.data(), bytes.size(), text.data() + b, n, nullptr, &bin_len,
                       nullptr) != 0 ||
        bin_len != kKeyBytes) {
      throw KeyError(where + "the key is not " + std::to_string(2 * kKeyBytes) + " hex digits" +
                     regen);
    }
    key_line = line_no;
  }
  if (key_line == 0) {
    throw KeyError(path + ": no key in the file (expected a line of " +
                   std::to_string(2 * kKeyBytes) + " hex digits after the '#' comments)" + regen);
  }
  if (sodium_is_zero(bytes.data(), bytes.size())) {
    throw KeyError(path + ":" + std::to_string(key_line) +
                   ": the key is all zeros, not a generated key" + regen);
  }
  return bytes;
}

// mkdir -p of the folders above `path`, each new one with mode 0700.
void MakeParents(const std::string& path) {
  for (std::size_t i = path.find('/', 1); i != std::string::npos; i = path.find('/', i + 1)) {
    const std::string dir = path.substr(0, i);
    if (mkdir(dir.c_str(), 0700) == 0) continue;
    const int err = errno;
    struct stat st;
    if (err == EEXIST && stat(dir.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) continue;
    throw KeyError("cannot create folder " + dir + " for the procman key " + path + ": " +
                   (err == EEXIST ? std::string("it exists and is not a folder")
                                  : std::string(std::strerror(err))));
  }
}

}  // namespace

std::string KeyId(const std::array<unsigned char, kKeyBytes>& bytes) {
  EnsureSodium();
  unsigned char out[crypto_generichash_BYTES_MIN];  // BLAKE2b's shortest output: 16 bytes
  static_assert(sizeof(out) >= kKeyIdBytes, "key id longer than the hash");
  crypto_generichash(out, sizeof(out), reinterpret_cast<const unsigned char*>(kKeyIdDomain),
                     sizeof(kKeyIdDomain) - 1, bytes.data(), bytes.size());
  return Hex(out, kKeyIdBytes);
}

std::array<uint8_t, kMacBytes> ComputeMac(const Key& key,
                                          const fusionloc::procman_signed_orders_t& envelope) {
  EnsureSodium();
  const std::vector<unsigned char> bytes = CanonicalBytes(envelope);
  std::array<uint8_t, kMacBytes> mac{};
  crypto_auth(mac.data(), bytes.data(), bytes.size(), key.bytes.data());
  return mac;
}

Key GenerateKey() {
  EnsureSodium();
  Key key;
  randombytes_buf(key.bytes.data(), key.bytes.size());
  key.id = KeyId(key.bytes);
  return key;
}

Key LoadKey(const std::string& path) {
  EnsureSodium();
  if (path.empty()) throw KeyError("no procman key file given (empty path)");
  // O_NONBLOCK: a FIFO planted at the path must not hang us; it is refused below.
  Fd fd{open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOCTTY | O_NONBLOCK)};
  if (fd.fd < 0) {
    const int err = errno;
    if (err == ENOENT)
      throw KeyError("procman key " + path + " does not exist: " + NewKeyHint(path));
    if (err == EACCES) {
      throw KeyError("procman key " + path + ": permission denied for uid " +
                     std::to_string(geteuid()) +
                     "; the key must belong to the user running this program, mode 0600");
    }
    throw KeyError("cannot open procman key " + path + ": " + std::strerror(err));
  }
  struct stat st;
  if (fstat(fd.fd, &st) != 0) {
    throw KeyError("cannot stat procman key " + path + ": " + std::strerror(errno));
  }
  if (S_ISDIR(st.st_mode)) {
    throw KeyError("procman key " + path + " is a folder: give the key file itself, e.g. " + path +
                   "/procman.key");
  }
  if (!S_ISREG(st.st_mode)) {
    throw KeyError("procman key " + path + " is not a regular file: remove it and " +
                   NewKeyHint(path));
  }
  if (st.st_uid != geteuid() && st.st_uid != 0) {
    throw KeyError("procman key " + path + " belongs to uid " + std::to_string(st.st_uid) +
                   ", not to the user running this program (uid " + std::to_string(geteuid()) +
                   ") or root, who could replace it; run `chown " + std::to_string(geteuid()) +
                   " " + path + "`");
  }
  const mode_t mode = st.st_mode & 07777;
  if (mode != 0600 && mode != 0400) {
    const bool open_to_others = (mode & 077) != 0;
    throw KeyError("procman key " + path + " has mode " + ModeString(mode) +
                   (open_to_others ? ": others on this host may read or change it, and with it "
                                     "command every deputy"
                                   : ": a key file must be mode 0600 or 0400") +
                   "; run `chmod 600 " + path + "`");
  }
  if (static_cast<std::size_t>(st.st_size) > kMaxKeyFileBytes) {
    throw KeyError("procman key " + path + " is " + std::to_string(st.st_size) +
                   " bytes, not a key file: " + NewKeyHint(path));
  }
  std::string text(kMaxKeyFileBytes + 1, '\0');
  Wipe wipe{text.data(), text.size()};
  std::size_t got = 0;
  while (got < text.size()) {
    const ssize_t n = read(fd.fd, text.data() + got, text.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw KeyError("cannot read procman key " + path + ": " + std::strerror(errno));
    if (n == 0) break;
    got += static_cast<std::size_t>(n);
  }
  if (got > kMaxKeyFileBytes) {
    throw KeyError("procman key " + path + " is larger than " + std::to_string(kMaxKeyFileBytes) +
                   " bytes, not a key file: " + NewKeyHint(path));
  }
  Key key;
  key.bytes = ParseKeyText(std::string_view(text.data(), got), path);
  key.id = KeyId(key.bytes);
  return key;
}

void WriteNewKey(const std::string& path) {
  EnsureSodium();
  if (path.empty()) throw KeyError("no file given for the new procman key (empty path)");
  MakeParents(path);
  Fd fd{open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC | O_NOFOLLOW, 0600)};
  if (fd.fd < 0) {
    const int err = errno;
    if (err == EEXIST) {
      throw KeyError("procman key " + path +
                     " already exists; not overwriting it (every deputy holding it would stop "
                     "obeying). Keep using it, or remove it first and copy the new key to every "
                     "host");
    }
    throw KeyError("cannot create procman key " + path + ": " + std::strerror(err));
  }
  const auto fail = [&](const std::string& what, int err) {
    unlink(path.c_str());
    return KeyError("cannot write procman key " + path + ": " + what + ": " + std::strerror(err));
  };
  if (fchmod(fd.fd, 0600) != 0) throw fail("chmod 600", errno);  // whatever the umask
  Key key = GenerateKey();
  Wipe wipe_key{key.bytes.data(), key.bytes.size()};
  std::string text = "# fusionloc procman key, id " + key.id +
                     " (libsodium crypto_auth, HMAC-SHA512-256).\n"
                     "# Secret: keep it mode 0600 and copy it only to the sheriff and deputy "
                     "hosts (docs/PROCMAN_SECURITY.md).\n" +
                     Hex(key.bytes.data(), key.bytes.size()) + "\n";
  Wipe wipe_text{text.data(), text.size()};
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = write(fd.fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw fail("write", n < 0 ? errno : EIO);
    done += static_cast<std::size_t>(n);
  }
  if (fsync(fd.fd) != 0) throw fail("fsync", errno);
  const int to_close = fd.fd;
  fd.fd = -1;
  if (close(to_close) != 0) throw fail("close", errno);
}

std::string ExistingDefaultKeyPath() {
  std::string path;
  try {
    path = DefaultKeyPath();
  } catch (const KeyError&) {
    return "";
  }
  return access(path.c_str(), F_OK) == 0 ? path : "";
}

std::string DefaultKeyPath() {
  const char* env = std::getenv("FUSIONLOC_PROCMAN_KEY");
  if (env != nullptr && env[0] != '\0') return env;
  if (geteuid() == 0) return "/etc/fusionloc/procman.key";
  const char* xdg = std::getenv("XDG_CONFIG_HOME");
  if (xdg != nullptr && xdg[0] == '/') return std::string(xdg) + "/fusionloc/procman.key";
  std::string home;
  if (const char* h = std::getenv("HOME"); h != nullptr && h[0] != '\0') {
    home = h;
  } else if (const passwd* pw = getpwuid(geteuid()); pw != nullptr && pw->pw_dir != nullptr) {
    home = pw->pw_dir;
  }
  if (home.empty()) {
    throw KeyError(
        "no default place for the procman key: neither $FUSIONLOC_PROCMAN_KEY, "
        "$XDG_CONFIG_HOME nor a home folder is set; pass --key FILE");
  }
  return home + "/.config/fusionloc/procman.key";
}

// ---- OrderSigner ----

OrderSigner::OrderSigner(Key key, std::string sheriff_id)
    : key_(std::move(key)), sheriff_id_(std::move(sheriff_id)) {
  EnsureSodium();
  if (sheriff_id_.empty()) throw std::invalid_argument("OrderSigner: empty sheriff id");
  CheckKeyId(key_, "OrderSigner");
}

OrderSigner::~OrderSigner() { sodium_memzero(key_.bytes.data(), key_.bytes.size()); }

fusionloc::procman_signed_orders_t OrderSigner::Sign(const std::vector<uint8_t>& encoded_orders2,
                                                     int64_t now_us) {
  if (encoded_orders2.size() > static_cast<std::size_t>(std::numeric_limits<int32_t>::max())) {
    throw std::invalid_argument("OrderSigner: orders of " + std::to_string(encoded_orders2.size()) +
                                " bytes do not fit an LCM array");
  }
  if (last_counter_ == std::numeric_limits<int64_t>::max()) {
    throw std::runtime_error("OrderSigner: counter exhausted");
  }
  fusionloc::procman_signed_orders_t e;
  e.utime = now_us;
  e.sheriff_id = sheriff_id_;
  e.key_id = key_.id;
  e.counter = std::max(last_counter_ + 1, now_us);
  e.orders_size = static_cast<int32_t>(encoded_orders2.size());
  e.orders = encoded_orders2;
  const std::vector<unsigned char> bytes = CanonicalBytes(e);
  crypto_auth(e.mac, bytes.data(), bytes.size(), key_.bytes.data());
  last_counter_ = e.counter;
  return e;
}

// ---- OrderVerifier ----

fl::Status OrderVerifier::Options::Validate() const {
  if (!std::isfinite(max_age_s) || max_age_s <= 0.0) {
    return fl::Status::Error("max_age_s must be a positive number of seconds (got " +
                             std::to_string(max_age_s) + "); libbot2 uses 60");
  }
  if (!std::isfinite(max_future_s) || max_future_s < 0.0) {
    return fl::Status::Error("max_future_s must be a number of seconds >= 0 (got " +
                             std::to_string(max_future_s) + ")");
  }
  return fl::Status::Ok();
}

OrderVerifier::OrderVerifier(std::vector<Key> keys, Options options)
    : keys_(std::move(keys)), options_(options) {
  EnsureSodium();
  if (keys_.empty()) throw std::invalid_argument("OrderVerifier: no keys given");
  for (const Key& k : keys_) CheckKeyId(k, "OrderVerifier");
  const fl::Status s = options_.Validate();
  if (!s.ok()) throw std::invalid_argument("OrderVerifier: " + s.message());
}

OrderVerifier::~OrderVerifier() {
  for (Key& k : keys_) sodium_memzero(k.bytes.data(), k.bytes.size());
}

OrderVerifier::Verdict OrderVerifier::Refuse(Verdict verdict, std::string detail) {
  ++counts_[static_cast<int>(verdict)];
  last_detail_ = std::string(Name(verdict)) + ": " + detail;
  return verdict;
}

OrderVerifier::Verdict OrderVerifier::Verify(const fusionloc::procman_signed_orders_t& e,
                                             int64_t now_us,
                                             std::vector<uint8_t>* encoded_orders2) {
  const std::string from = " from sheriff " + Printable(e.sheriff_id);
  if (e.orders_size < 0 || static_cast<std::size_t>(e.orders_size) != e.orders.size()) {
    return Refuse(Verdict::kMalformed, "orders_size " + std::to_string(e.orders_size) + " but " +
                                           std::to_string(e.orders.size()) + " bytes of orders" +
                                           from);
  }
  if (e.sheriff_id.empty()) return Refuse(Verdict::kMalformed, "empty sheriff_id");
  if (e.key_id.empty()) return Refuse(Verdict::kMalformed, "empty key_id" + from);

  const Key* key = nullptr;
  for (const Key& k : keys_) {
    if (k.id == e.key_id) {  // ids are public: no need for a constant-time compare
      key = &k;
      break;
    }
  }
  if (key == nullptr) {
    std::string known;
    for (const Key& k : keys_) known += (known.empty() ? "" : ", ") + k.id;
    return Refuse(Verdict::kUnknownKey, "key id " + Printable(e.key_id) + from +
                                            " is not one of this deputy's keys (" + known + ")");
  }

  const std::vector<unsigned char> bytes = CanonicalBytes(e);
  if (crypto_auth_verify(e.mac, bytes.data(), bytes.size(), key->bytes.data()) != 0) {
    return Refuse(Verdict::kBadMac, "MAC does not match key " + key->id + from +
                                        " (forged or altered, or signed with another key "
                                        "of the same id)");
  }

  // Only an authentic envelope gets here: its utime and counter are the sheriff's.
  const double age_s = (static_cast<double>(now_us) - static_cast<double>(e.utime)) * 1e-6;
  char buf[160];
  if (age_s > options_.max_age_s) {
    std::snprintf(buf, sizeof(buf), "utime %.1f s old (max_age_s %g)", age_s, options_.max_age_s);
    return Refuse(Verdict::kStale, buf + from);
  }
  if (-age_s > options_.max_future_s) {
    std::snprintf(buf, sizeof(buf), "utime %.1f s in the future (max_future_s %g)", -age_s,
                  options_.max_future_s);
    return Refuse(Verdict::kStale,
                  buf + from + ": are the sheriff's and this host's clocks synchronised?");
  }
  const auto it = last_counter_.find(e.sheriff_id);
  if (it != last_counter_.end() && e.counter <= it->second) {
    return Refuse(Verdict::kReplayed, "counter " + std::to_string(e.counter) +
                                          " is not above the last accepted " +
                                          std::to_string(it->second) + from);
  }
  last_counter_[e.sheriff_id] = e.counter;
  if (encoded_orders2 != nullptr) *encoded_orders2 = e.orders;
  ++counts_[static_cast<int>(Verdict::kOk)];
  last_detail_.clear();
  return Verdict::kOk;
}

int64_t OrderVerifier::count(Verdict verdict) const {
  const int i = static_cast<int>(verdict);
  return i >= 0 && i < kNumVerdicts ? counts_[i] : 0;
}

const char* OrderVerifier::Name(Verdict verdict) {
  switch (verdict) {
    case Verdict::kOk:
      return "ok";
    case Verdict::kMalformed:
      return "malformed";
    case Verdict::kUnknownKey:
      return "unknown key id";
    case Verdict::kBadMac:
      return "bad MAC";
    case Verdict::kStale:
      return "stale";
    case Verdict::kReplayed:
      return "replayed";
  }
  return "unknown verdict";
}

}  // namespace fl::procman

#include "fusionloc/common/state_buffer.hpp"

namespace fl {
namespace {
constexpr uint32_t kByteOrderMark = 0x01020304u;
}  // namespace

void StateWriter::Begin(const std::string& magic, uint32_t version) {
  bytes_.insert(bytes_.end(), magic.begin(), magic.end());
  Put(kByteOrderMark);
  Put(version);
}

void StateWriter::Put(const std::string& s) {
  PutCount(s.size());
  bytes_.insert(bytes_.end(), s.begin(), s.end());
}

void StateWriter::Put(const Pose2& p) {
  Put(p.x);
  Put(p.y);
  Put(p.theta);
}

void StateReader::Begin(const std::string& magic, uint32_t version) {
  field_ = pos_;
  if (size_ - pos_ < magic.size() || std::memcmp(data_ + pos_, magic.data(), magic.size()) != 0) {
    Fail("not a saved state of this kind (expected \"" + magic + "\" here)");
  }
  pos_ += magic.size();
  if (Get<uint32_t>("byte-order mark") != kByteOrderMark) {
    Fail("written on a machine of another byte order");
  }
  const uint32_t v = Get<uint32_t>("version");
  if (v != version) {
    Fail("version " + std::to_string(v) + ", this program reads version " +
         std::to_string(version));
  }
}

bool StateReader::GetBool(const char* what) {
  const uint8_t b = Get<uint8_t>(what);
  if (b > 1) Fail(std::string(what) + ": " + std::to_string(b) + " is not a boolean");
  return b == 1;
}

std::string StateReader::GetString(const char* what) {
  const size_t n = Count(1, what);  // n bytes are left
  std::string s(reinterpret_cast<const char*>(data_ + pos_), n);
  pos_ += n;
  return s;
}

Pose2 StateReader::GetPose2(const char* what) {
  Pose2 p;
  p.x = Get<double>(what);
  p.y = Get<double>(what);
  p.theta = Get<double>(what);
  return p;
}

size_t StateReader::Count(size_t min_element_bytes, const char* what) {
  const uint64_t n = Get<uint64_t>(what);  // sets field_
  const size_t left = size_ - pos_;
  if (min_element_bytes > 0 && n > left / min_element_bytes) {
    Fail(std::string(what) + ": a count of " + std::to_string(n) + " does not fit in the " +
         std::to_string(left) + " bytes left");
  }
  return static_cast<size_t>(n);
}

void StateReader::End(const char* what) {
  field_ = pos_;
  if (pos_ != size_) {
    Fail(std::to_string(size_ - pos_) + " bytes after the end of the " + std::string(what));
  }
}

void StateReader::Fail(const std::string& message) const {
  throw StateError("saved state, at byte " + std::to_string(field_) + ": " + message);
}

void StateReader::Need(size_t n, const char* what) const {
  if (size_ - pos_ < n) {
    Fail(std::string("truncated: ") + what + " needs " + std::to_string(n) + " bytes, " +
         std::to_string(size_ - pos_) + " left");
  }
}

}  // namespace fl

// Byte buffers for a process's saved state (the fusion's journal snapshot, FUSION.md
// "Respawn"): plain values appended in this machine's byte order and read back with every
// read bounds-checked, so that a damaged or hostile buffer is an error naming the byte
// offset, never a read past its end or an allocation of a size it merely claims.
//
// The state is written and read by the same program on the same machine (a respawn), so the
// layout is the host's; StateWriter::Begin/StateReader::Begin put a magic, a version and a
// byte-order mark first and refuse a buffer that does not match.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "fusionloc/common/geometry.hpp"

namespace fl {

// A buffer that cannot be read: its message names the byte offset and what was expected.
class StateError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class StateWriter {
 public:
  StateWriter() = default;
  // Writes into `buffer`, cleared but with its capacity kept: a process that saves its state
  // often reuses one buffer instead of allocating megabytes each time (which glibc's heap
  // does not give back: the fusion's RSS grew 4 MB per 10 minutes that way).
  explicit StateWriter(std::vector<uint8_t> buffer) : bytes_(std::move(buffer)) { bytes_.clear(); }
  // Magic (e.g. "FLFUSNAP"), then the version and a byte-order mark.
  void Begin(const std::string& magic, uint32_t version);

  template <class T>
  void Put(const T& value) {
    static_assert(std::is_arithmetic_v<T>, "Put takes numbers; use the overloads");
    const auto* p = reinterpret_cast<const uint8_t*>(&value);
    bytes_.insert(bytes_.end(), p, p + sizeof(T));
  }
  void Put(const std::string& s);
  void Put(const Pose2& p);
  template <class Scalar, int R, int C>
  void Put(const Eigen::Matrix<Scalar, R, C>& m) {
    static_assert(R > 0 && C > 0, "fixed-size matrices only");
    for (int c = 0; c < C; ++c)
      for (int r = 0; r < R; ++r) Put(m(r, c));
  }
  // A count before a sequence (read back by StateReader::Count with its element size).
  void PutCount(size_t n) { Put(static_cast<uint64_t>(n)); }

  const std::vector<uint8_t>& bytes() const { return bytes_; }
  std::vector<uint8_t> Release() { return std::move(bytes_); }

 private:
  std::vector<uint8_t> bytes_;
};

class StateReader {
 public:
  StateReader(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  // Checks the magic, the byte order and the version; throws StateError if they differ.
  void Begin(const std::string& magic, uint32_t version);

  template <class T>
  T Get(const char* what) {
    static_assert(std::is_arithmetic_v<T>, "Get reads numbers; use the overloads");
    field_ = pos_;
    Need(sizeof(T), what);
    T value;
    std::memcpy(&value, data_ + pos_, sizeof(T));
    pos_ += sizeof(T);
    return value;
  }
  bool GetBool(const char* what);
  std::string GetString(const char* what);
  Pose2 GetPose2(const char* what);
  template <class Scalar, int R, int C>
  void Get(Eigen::Matrix<Scalar, R, C>* m, const char* what) {
    for (int c = 0; c < C; ++c)
      for (int r = 0; r < R; ++r) (*m)(r, c) = Get<Scalar>(what);
  }
  // A count of elements that each take at least `min_element_bytes` in the buffer: refused if
  // the bytes left cannot hold that many (before anything is allocated for them).
  size_t Count(size_t min_element_bytes, const char* what);

  size_t offset() const { return pos_; }
  bool at_end() const { return pos_ == size_; }
  // Throws unless every byte was read.
  void End(const char* what);
  // Throws StateError("saved state, at byte OFFSET: MESSAGE"), OFFSET where the last field
  // read (or the one that could not be read) starts.
  [[noreturn]] void Fail(const std::string& message) const;

 private:
  void Need(size_t n, const char* what) const;

  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
  size_t field_ = 0;  // where the last field read starts
};

}  // namespace fl

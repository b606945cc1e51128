#include "fusionloc/viewer/frame.hpp"

#include <chrono>
#include <cstring>

namespace fl::viewer {

Frame MakeFrame(std::string key, const std::string& header_json, const void* payload,
                size_t payload_size) {
  Frame f;
  f.key = std::move(key);
  const uint32_t n = static_cast<uint32_t>(header_json.size());
  const size_t padded = (4 + n + 3) / 4 * 4;
  f.bytes.assign(padded + payload_size, '\0');
  for (int i = 0; i < 4; ++i) f.bytes[i] = static_cast<char>((n >> (8 * i)) & 0xff);
  std::memcpy(&f.bytes[4], header_json.data(), n);
  if (payload_size > 0) std::memcpy(&f.bytes[padded], payload, payload_size);
  return f;
}

bool DecodeFrame(const std::string& bytes, std::string* header_json, std::string* payload) {
  if (bytes.size() < 4) return false;
  uint32_t n = 0;
  for (int i = 0; i < 4; ++i) n |= static_cast<uint32_t>(static_cast<uint8_t>(bytes[i])) << (8 * i);
  const size_t padded = (4 + static_cast<size_t>(n) + 3) / 4 * 4;
  if (4 + static_cast<size_t>(n) > bytes.size() || padded > bytes.size()) return false;
  *header_json = bytes.substr(4, n);
  *payload = bytes.substr(padded);
  return true;
}

FrameQueue::FrameQueue(size_t capacity) : capacity_(capacity < 1 ? 1 : capacity) {}

void FrameQueue::Push(Frame frame) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (closed_) return;
    if (!frame.key.empty()) {
      for (Frame& queued : frames_) {
        if (queued.key == frame.key) {
          queued = std::move(frame);
          ++replaced_;
          return;
        }
      }
    }
    while (frames_.size() >= capacity_) {
      frames_.pop_front();
      ++dropped_;
    }
    frames_.push_back(std::move(frame));
  }
  cv_.notify_one();
}

bool FrameQueue::Pop(Frame* frame, int timeout_ms) {
  std::unique_lock<std::mutex> lock(mutex_);
  cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms),
               [this] { return closed_ || !frames_.empty(); });
  if (closed_ || frames_.empty()) return false;
  *frame = std::move(frames_.front());
  frames_.pop_front();
  return true;
}

void FrameQueue::Close() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    frames_.clear();
  }
  cv_.notify_all();
}

size_t FrameQueue::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return frames_.size();
}
int64_t FrameQueue::dropped() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return dropped_;
}
int64_t FrameQueue::replaced() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return replaced_;
}
bool FrameQueue::closed() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return closed_;
}

}  // namespace fl::viewer

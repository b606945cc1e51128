// One message of the viewer to the browser (a binary WebSocket message), and the per-client
// queue that keeps a slow browser from ever blocking the process that feeds it.
//
// Wire format of a frame (little-endian):
//   uint32 n | n bytes of JSON header | zero padding to a multiple of 4 bytes | payload
// The header's "type" says what it is (docs/VIEWER.md lists them); the payload, if any, is a
// packed array (float32 or int8) whose layout the header gives, aligned for a typed-array view.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>

namespace fl::viewer {

struct Frame {
  // Frames with the same non-empty key carry the whole state of one thing (the grid, one
  // trajectory, the status table): a newer one replaces a queued older one. An empty key
  // (appended trail points, new cloud voxels) is never replaced.
  std::string key;
  std::string bytes;  // the encoded message
};

// Encodes a frame: `header_json` must be a JSON object.
Frame MakeFrame(std::string key, const std::string& header_json, const void* payload = nullptr,
                size_t payload_size = 0);
// Splits an encoded frame (tests, tools): false if it is malformed.
bool DecodeFrame(const std::string& bytes, std::string* header_json, std::string* payload);

// A bounded queue of frames for one client, filled by the process and emptied by the client's
// sender thread. Push never blocks: a frame with the key of a queued one replaces it in place,
// and when the queue is full the oldest frame is dropped (and counted).
class FrameQueue {
 public:
  explicit FrameQueue(size_t capacity);

  void Push(Frame frame);
  // Waits up to `timeout_ms` for a frame; false on timeout or once closed and empty.
  bool Pop(Frame* frame, int timeout_ms);
  // Wakes the sender; Pop returns false from now on.
  void Close();

  size_t size() const;
  int64_t dropped() const;   // frames dropped because the queue was full
  int64_t replaced() const;  // frames superseded by a newer one of the same key
  bool closed() const;

 private:
  const size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Frame> frames_;
  int64_t dropped_ = 0, replaced_ = 0;
  bool closed_ = false;
};

}  // namespace fl::viewer

// The time slider of log mode (fl-viewer --log): a clock over a log's time span that plays,
// pauses, seeks and changes speed on the browser's commands.
#pragma once

#include <string>

#include "fusionloc/common/time.hpp"

namespace fl::viewer {

// A browser command: "play", "pause", "seek T" (T in seconds from the log's start),
// "speed S" (S > 0, times real time).
struct PlaybackCommand {
  enum Kind { kPlay, kPause, kSeek, kSpeed } kind = kPlay;
  double value = 0;
};
// False (and *error set) for anything else.
bool ParsePlaybackCommand(const std::string& text, PlaybackCommand* command, std::string* error);

class PlaybackClock {
 public:
  PlaybackClock(Utime start, Utime end, double speed = 1.0, bool playing = true);

  void Apply(const PlaybackCommand& command);
  // Moves the clock on by `wall_s` of real time (at the speed, if playing); stops at the end.
  void Advance(double wall_s);

  Utime now() const { return now_; }
  Utime start() const { return start_; }
  Utime end() const { return end_; }
  bool playing() const { return playing_; }
  double speed() const { return speed_; }
  // Set by a seek, until taken: the view must be rebuilt at now().
  bool TakeSeek();
  // "clock" frame header: {"type":"clock", "utime", "start", "end", "playing", "speed"}.
  std::string Json() const;

 private:
  Utime start_, end_, now_;
  double speed_;
  bool playing_;
  bool seeked_ = true;  // the first view is built at start()
};

}  // namespace fl::viewer

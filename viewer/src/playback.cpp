#include "fusionloc/viewer/playback.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "fusionloc/common/json.hpp"

namespace fl::viewer {

bool ParsePlaybackCommand(const std::string& text, PlaybackCommand* command, std::string* error) {
  std::istringstream in(text);
  std::string verb;
  in >> verb;
  if (verb == "play" || verb == "pause") {
    command->kind = verb == "play" ? PlaybackCommand::kPlay : PlaybackCommand::kPause;
    return true;
  }
  if (verb == "seek" || verb == "speed") {
    double v = 0;
    if (!(in >> v) || !std::isfinite(v) || (verb == "speed" && !(v > 0 && v <= 1000))) {
      *error = "'" + text + "': " + verb + " needs a number" +
               (verb == "speed" ? " in (0, 1000]" : " (seconds from the start)");
      return false;
    }
    command->kind = verb == "seek" ? PlaybackCommand::kSeek : PlaybackCommand::kSpeed;
    command->value = v;
    return true;
  }
  *error = "'" + text + "': unknown command (play, pause, seek T, speed S)";
  return false;
}

PlaybackClock::PlaybackClock(Utime start, Utime end, double speed, bool playing)
    : start_(start), end_(std::max(start, end)), now_(start), speed_(speed), playing_(playing) {}

void PlaybackClock::Apply(const PlaybackCommand& c) {
  switch (c.kind) {
    case PlaybackCommand::kPlay:
      if (now_ >= end_) {  // from the end: play again from the start
        now_ = start_;
        seeked_ = true;
      }
      playing_ = true;
      break;
    case PlaybackCommand::kPause:
      playing_ = false;
      break;
    case PlaybackCommand::kSeek:
      now_ = std::clamp(start_ + SecondsToUtime(c.value), start_, end_);
      seeked_ = true;
      break;
    case PlaybackCommand::kSpeed:
      speed_ = c.value;
      break;
  }
}

void PlaybackClock::Advance(double wall_s) {
  if (!playing_) return;
  now_ = std::min(end_, now_ + SecondsToUtime(wall_s * speed_));
  if (now_ >= end_) playing_ = false;
}

bool PlaybackClock::TakeSeek() {
  const bool s = seeked_;
  seeked_ = false;
  return s;
}

std::string PlaybackClock::Json() const {
  std::ostringstream h;
  h << "{\"type\":\"clock\",\"utime\":" << now_ << ",\"start\":" << start_ << ",\"end\":" << end_
    << ",\"playing\":" << (playing_ ? "true" : "false") << ",\"speed\":" << JsonNumber(speed_)
    << "}";
  return h.str();
}

}  // namespace fl::viewer

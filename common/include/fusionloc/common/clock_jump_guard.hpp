// ClockJumpGuard: rejects the items of one stream whose time stamps run ahead of their
// arrival, i.e. a clock that jumped forward (or a corrupted stamp far in the future), which
// would otherwise be accepted and then make every later, correct item look late.
//
// Between two accepted items the stamps may advance by at most the time that passed between
// their arrivals (receive time live, log time in replay) plus max_lead_us. Check() only looks;
// the consumer calls Accept() for the items it took, so neither a rejected item nor one the
// consumer refused for another reason (a stamp going backwards, a NaN) moves the baseline,
// and the stream is accepted again as soon as its stamps agree with its arrivals.
// StreamMerger checks the same against the other streams still arriving; this guard needs
// none.
#pragma once

#include <string>

#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"

namespace fl {

class ClockJumpGuard {
 public:
  // max_lead_us [us]: how much faster than their arrivals the stamps may advance.
  explicit ClockJumpGuard(Utime max_lead_us = 1000000) : max_lead_us_(max_lead_us) {}

  // Ok or an error naming the jump; anything is Ok before the first Accept().
  Status Check(const std::string& stream, Utime utime, Utime arrival) const {
    if (!have_) return Status::Ok();
    const Utime stamp_step = utime - last_utime_;
    const Utime arrival_step = arrival - last_arrival_;
    if (stamp_step > arrival_step + max_lead_us_) {
      return Status::Error(stream + ": time stamp " + FormatUtime(utime) + " is " +
                           FormatDouble(1e-6 * static_cast<double>(stamp_step - arrival_step)) +
                           " s further ahead than its arrival: its clock jumped forward; "
                           "dropped until the stamps agree with the arrivals again");
    }
    return Status::Ok();
  }
  // The consumer took the item: the baseline of the next Check().
  void Accept(Utime utime, Utime arrival) {
    have_ = true;
    last_utime_ = utime;
    last_arrival_ = arrival;
  }

 private:
  Utime max_lead_us_;
  bool have_ = false;
  Utime last_utime_ = 0;
  Utime last_arrival_ = 0;
};

}  // namespace fl

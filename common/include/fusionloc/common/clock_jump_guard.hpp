// ClockJumpGuard: rejects the items of one stream whose time stamps run ahead of their
// arrival, i.e. a clock that jumped forward (or a corrupted stamp far in the future), which
// would otherwise be accepted and then make every later, correct item look late.
//
// Between two accepted items the stamps may advance by at most the time that passed between
// their arrivals (receive time live, log time in replay) plus max_lead_us. A rejected item
// changes nothing, so the stream is accepted again as soon as its stamps agree with its
// arrivals. Stamps going backwards are not this class's business (the consumer rejects them).
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

  // Ok (and remembered) or an error naming the jump. The first item is accepted.
  Status Check(const std::string& stream, Utime utime, Utime arrival) {
    if (have_) {
      const Utime stamp_step = utime - last_utime_;
      const Utime arrival_step = arrival - last_arrival_;
      if (stamp_step > arrival_step + max_lead_us_) {
        return Status::Error(stream + ": time stamp " + FormatUtime(utime) + " is " +
                             FormatDouble(1e-6 * static_cast<double>(stamp_step - arrival_step)) +
                             " s further ahead than its arrival: its clock jumped forward; "
                             "dropped until the stamps agree with the arrivals again");
      }
    }
    have_ = true;
    last_utime_ = utime;
    last_arrival_ = arrival;
    return Status::Ok();
  }

 private:
  Utime max_lead_us_;
  bool have_ = false;
  Utime last_utime_ = 0;
  Utime last_arrival_ = 0;
};

}  // namespace fl

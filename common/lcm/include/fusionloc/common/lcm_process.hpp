// The LCM side of the process edge (on top of fusionloc/common/program.hpp).
//
// A process is an adapter (an LcmNode: subscribes, converts, calls its library, publishes) and
// a short main that declares its options:
//
//   int main(int argc, char** argv) {
//     fl::Program program("fl-foo", "What it does.");
//     FooOptions options;
//     program.AddOptions(&options, "config/foo.yaml");
//     fl::LcmProcess process(&program, FooNode::Inputs(), FooNode::Outputs());
//     if (!program.Parse(argc, argv)) return program.exit_code();
//     return program.Run([&] {
//       return process.Run([&](fl::LcmInterface* lcm, const fl::ChannelMap& channels) {
//         return std::make_unique<FooNode>(options, lcm, channels);
//       });
//     });
//   }
//
// LcmProcess adds --lcm-url, --channel NAME=OTHER and --input-timeout-s, lists the channels in
// --help, opens LCM, stops cleanly on SIGINT/SIGTERM, and never fails silently:
//  - live, a required input that has been silent for --input-timeout-s is logged and set as
//    the status' warning ("no LASER on udpm://... for 5 s: is the driver running? ...");
//  - replaying a log, an input that is not an LCM log, or one with none of a required channel,
//    ends with exit code 1 naming what is missing and what the log holds.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "fusionloc/common/channel_map.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/status_reporter.hpp"

namespace fl {

// A channel a process reads or writes, for --help and for the input checks.
struct ChannelSpec {
  std::string name;  // default channel name, e.g. "LASER"
  std::string type;  // LCM type, e.g. "bot_core.planar_lidar_t"
  std::string what;  // one line: what it carries
};

// An adapter between LCM and one library: subscribes in its constructor, publishes from its
// handlers and Poll(), and flushes in Finish().
class LcmNode {
 public:
  virtual ~LcmNode() = default;
  // Its status reporter (STATUS_<PROGRAM>); the edge ticks it and reports silent inputs on it.
  virtual StatusReporter& status() = 0;
  // The (renamed) channels without which it produces nothing.
  virtual std::vector<std::string> RequiredInputs() const = 0;
  // Called after every batch of handled messages and at least every 100 ms.
  virtual void Poll() {}
  // The input has ended (end of the log, or shutdown): process what is queued and publish the
  // final outputs.
  virtual void Finish() {}
  // One line for the log at the end ("scans 1001, keyframes 69, ...").
  virtual std::string Summary() const { return ""; }
  // Non-empty when the node could not do what it was asked to (e.g. save the map it was asked
  // to save, on a full disk): the process reports it and exits non-zero after finishing.
  virtual std::string Failure() const { return ""; }
};

using MakeNode =
    std::function<std::unique_ptr<LcmNode>(LcmInterface* lcm, const ChannelMap& channels)>;

// Watches the required inputs of nodes: counts what arrives on each and, live, reports one
// that has been silent for `timeout_s` (once per silence, and again when it comes back).
class InputWatch {
 public:
  InputWatch(LcmInterface* lcm, double timeout_s);
  // Watches `channel` for `node` (which is told through its status).
  void Watch(const std::string& channel, LcmNode* node);
  // Live: checks the silences (wall clock). Call often.
  void Poll();
  int64_t received(const std::string& channel) const;
  // The watched channels that received nothing.
  std::vector<std::string> Silent() const;

 private:
  struct Entry {
    std::string channel;
    std::vector<LcmNode*> nodes;
    int64_t count = 0;
    Utime last_utime = 0;  // monotonic [us] of the last message (or of the start)
    bool warned = false;
  };
  LcmInterface* lcm_;
  double timeout_s_;
  std::vector<std::unique_ptr<Entry>> entries_;
};

// Runs nodes on one LCM interface until shutdown or the end of the log: handles messages,
// polls the nodes and the watch, ticks their status; then finishes them in order (delivering
// what each one's Finish() published before the next one finishes, so that a pipeline in one
// process drains like separate processes do). `progress`, if set, is called about twice a
// second in log mode with the fraction read.
void SpinNodes(LcmInterface* lcm, const std::vector<LcmNode*>& nodes, InputWatch* watch,
               const std::function<void(double)>& progress = {});

// "LASER (1001), ODOMETRY (1001), ..." of a log's channel counts ("nothing" if empty).
std::string DescribeLogChannels(const std::map<std::string, int64_t>& counts);

class LcmProcess {
 public:
  // Adds the LCM flags to `program` and the channel lists to its --help.
  LcmProcess(Program* program, std::vector<ChannelSpec> inputs, std::vector<ChannelSpec> outputs);

  const std::string& url() const { return url_; }
  const ChannelMap& channels() const { return channels_; }

  // Opens LCM (throws UsageError for a malformed URL, std::runtime_error if it cannot be
  // opened) and installs the SIGINT/SIGTERM handlers.
  std::unique_ptr<LcmInterface> Open() const;

  // The whole life of a node: Open(), make the node, SpinNodes(), then in log mode check that
  // the log held the required inputs. Returns the exit code (0, or 1 with the reason printed).
  int Run(const MakeNode& make_node) const;

 private:
  Program* program_;
  std::vector<ChannelSpec> inputs_, outputs_;
  std::string url_;
  std::vector<std::string> channel_specs_;
  ChannelMap channels_;
  double input_timeout_s_ = 5.0;
};

}  // namespace fl

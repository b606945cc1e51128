#include "fusionloc/common/lcm_process.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <sstream>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/number_format.hpp"
#include "fusionloc/common/process_memory.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/status_t.hpp"

namespace fl {

InputWatch::InputWatch(LcmInterface* lcm, double timeout_s) : lcm_(lcm), timeout_s_(timeout_s) {}

void InputWatch::Watch(const std::string& channel, LcmNode* node) {
  for (auto& e : entries_) {
    if (e->channel == channel) {
      e->nodes.push_back(node);
      return;
    }
  }
  entries_.push_back(std::make_unique<Entry>());
  Entry* e = entries_.back().get();
  e->channel = channel;
  e->nodes.push_back(node);
  e->last_utime = MonotonicUtime();
  lcm_->SubscribeRaw(channel, [this, e](const std::string&, const void*, int, Utime) {
    ++e->count;
    const Utime now = MonotonicUtime();
    if (e->warned) {
      FL_LOG(INFO) << e->channel << " is back after "
                   << FormatDouble(std::round(UtimeToSeconds(now - e->last_utime) * 10) / 10)
                   << " s of silence";
      e->warned = false;
    }
    e->last_utime = now;
  });
}

void InputWatch::Poll() {
  if (lcm_->replaying() || timeout_s_ <= 0) return;
  const Utime now = MonotonicUtime();
  for (auto& e : entries_) {
    if (e->warned || UtimeToSeconds(now - e->last_utime) < timeout_s_) continue;
    e->warned = true;
    const std::string msg = "no " + e->channel + (e->count == 0 ? "" : " any more") + " on " +
                            lcm_->url() + " for " + FormatDouble(timeout_s_) +
                            " s: is the driver (or the process that publishes it) running? is "
                            "multicast routed?";
    FL_LOG(WARN) << msg;
    for (LcmNode* node : e->nodes) {
      node->status().SetState(fusionloc::status_t::LEVEL_WARN, msg);
      node->status().Tick(true);
    }
  }
}

int64_t InputWatch::received(const std::string& channel) const {
  for (const auto& e : entries_) {
    if (e->channel == channel) return e->count;
  }
  return 0;
}

std::vector<std::string> InputWatch::Silent() const {
  std::vector<std::string> out;
  for (const auto& e : entries_) {
    if (e->count == 0) out.push_back(e->channel);
  }
  return out;
}

namespace {

constexpr Utime kHeapHousekeepingPeriodUs = 60'000'000;

// Once a minute: the heap in use and what the allocator held freed, in every node's STATUS
// (heap_mb, heap_free_mb; live only: a replay's output does not depend on the machine), then
// the free pages go back to the system (process_memory.hpp).
void HeapHousekeeping(const std::vector<LcmNode*>& nodes, bool replay) {
  const HeapUsage heap = ReadHeapUsage();
  if (!heap.supported) return;
  if (!replay) {
    for (LcmNode* n : nodes) {
      n->status().Set("heap_mb", heap.in_use_mb);
      n->status().Set("heap_free_mb", heap.free_mb);
    }
  }
  ReturnFreeHeapToSystem();
}

}  // namespace

void SpinNodes(LcmInterface* lcm, const std::vector<LcmNode*>& nodes, InputWatch* watch,
               const std::function<void(double)>& progress) {
  const bool replay = lcm->replaying();
  Utime last_progress = MonotonicUtime();
  Utime last_heap = 0;
  while (!ShutdownRequested()) {
    const int rc = lcm->HandleSubscriptions(100);
    if (MonotonicUtime() - last_heap >= kHeapHousekeepingPeriodUs) {
      last_heap = MonotonicUtime();
      HeapHousekeeping(nodes, replay);
    }
    for (LcmNode* n : nodes) {
      n->Poll();
      n->status().Tick();
    }
    if (watch) watch->Poll();
    if (progress && replay && MonotonicUtime() - last_progress >= 500000) {
      last_progress = MonotonicUtime();
      progress(lcm->LogProgress());
    }
    if (rc < 0) break;
  }
  // Finish in pipeline order; in log mode deliver what each Finish() published (and what that
  // caused) before the next node finishes.
  for (LcmNode* n : nodes) {
    n->Finish();
    while (replay && lcm->HandleSubscriptions(0) > 0) {
      for (LcmNode* m : nodes) m->Poll();
    }
  }
  for (LcmNode* n : nodes) n->status().Tick(true);
  if (progress && replay) progress(1.0);
}

std::string DescribeLogChannels(const std::map<std::string, int64_t>& counts) {
  if (counts.empty()) return "nothing";
  std::string s;
  for (const auto& kv : counts) {
    s += (s.empty() ? "" : ", ") + kv.first + " (" + std::to_string(kv.second) + ")";
  }
  return s;
}

namespace {

std::string ChannelTable(const char* title, const std::vector<ChannelSpec>& list) {
  if (list.empty()) return "";
  size_t w = 0, t = 0;
  for (const auto& c : list) {
    w = std::max(w, c.name.size());
    t = std::max(t, c.type.size());
  }
  std::ostringstream s;
  s << title << ":\n";
  for (const auto& c : list) {
    s << "  " << c.name << std::string(w - c.name.size() + 2, ' ') << c.type
      << std::string(t - c.type.size() + 2, ' ') << c.what << "\n";
  }
  return s.str();
}

}  // namespace

LcmProcess::LcmProcess(Program* program, std::vector<ChannelSpec> inputs,
                       std::vector<ChannelSpec> outputs)
    : program_(program),
      inputs_(std::move(inputs)),
      outputs_(std::move(outputs)),
      url_(kDefaultLcmUrl) {
  CommandLine& cli = program->cli();
  cli.AddFlag("lcm-url", &url_,
              "LCM URL: udpm://GROUP:PORT?ttl=0 live, memq:// in one process, or "
              "log:IN.lcmlog[,OUT.lcmlog] to replay a log at full speed (outputs to OUT)");
  cli.AddRepeatedFlag("channel", &channel_specs_,
                      "use channel OTHER instead of NAME, as NAME=OTHER (e.g. LASER=FRONT_LASER)");
  cli.AddFlag("input-timeout-s", &input_timeout_s_,
              "live: warn (log and status) when a required input is silent this long [s]");
  std::vector<ChannelSpec> out = outputs_;
  out.push_back({StatusChannel(program->name()), "fusionloc.status_t",
                 "health, about once a second (data time in log mode)"});
  cli.AddEpilog("\n" + ChannelTable("Inputs", inputs_) + ChannelTable("Outputs", out));
  cli.AddCheck([this]() -> std::string {
    std::vector<std::string> known;
    for (const auto& c : inputs_) known.push_back(c.name);
    for (const auto& c : outputs_) known.push_back(c.name);
    for (const auto& spec : channel_specs_) {
      const std::string error = channels_.Add(spec, known);
      if (!error.empty()) return error;
    }
    if (!(input_timeout_s_ >= 0)) return "--input-timeout-s must be >= 0 (0: never warn)";
    return "";
  });
}

std::unique_ptr<LcmInterface> LcmProcess::Open() const {
  auto lcm = MakeLcm(url_);
  InstallShutdownHandlers();
  return lcm;
}

int LcmProcess::Run(const MakeNode& make_node) const {
  std::unique_ptr<LcmInterface> lcm = Open();
  std::unique_ptr<LcmNode> node = make_node(lcm.get(), channels_);
  InputWatch watch(lcm.get(), input_timeout_s_);
  std::string required;
  for (const auto& ch : node->RequiredInputs()) {
    watch.Watch(ch, node.get());
    required += (required.empty() ? "" : ", ") + ch;
  }
  if (required.empty()) {
    FL_LOG(INFO) << "running on " << lcm->url() << " (no inputs)";
  } else {
    FL_LOG(INFO) << "listening on " << required << " (" << lcm->url() << ")";
  }
  SpinNodes(lcm.get(), {node.get()}, &watch);
  const std::string summary = node->Summary();
  if (!summary.empty()) FL_LOG(INFO) << summary;
  const std::string failure = node->Failure();
  if (!failure.empty()) {
    FL_LOG(ERROR) << failure;
    return kExitFailure;
  }
  if (!lcm->replaying()) return kExitOk;
  const auto counts = lcm->LogChannelCounts();
  const std::string log =
      url_.substr(4, url_.find(',') == std::string::npos ? std::string::npos : url_.find(',') - 4);
  if (counts.empty()) {
    const std::string problems = lcm->LogProblems();
    FL_LOG(ERROR) << "'" << log << "' holds no LCM event"
                  << (problems.empty() ? " (the file is empty)" : ": " + problems)
                  << "; is it an LCM log (written by lcm-logger, fl-sim --log, fl-replay)?";
    return kExitFailure;
  }
  const std::vector<std::string> silent = watch.Silent();
  if (!silent.empty()) {
    std::string missing;
    for (const auto& ch : silent) missing += (missing.empty() ? "" : ", ") + ch;
    FL_LOG(ERROR) << "the log '" << log << "' has no " << missing << ", which " << program_->name()
                  << " needs; it holds " << DescribeLogChannels(counts)
                  << ". If the data is there under another name, use --channel NAME=OTHER; to "
                     "run the whole pipeline over a sensor log, use fl-replay";
    return kExitFailure;
  }
  return kExitOk;
}

}  // namespace fl

// RetiredTrajectory: the frozen fused poses of the fusion's nodes that left the optimised graph
// (FactorGraphFusion, BOUNDED GRAPH), in time order: one record per laser scan, 64 bytes, so a
// robot scanning at 10 Hz adds 2.3 MB an hour. Append-only: a record never changes once retired.
//
// In memory by default (a replay of a finite log). Given a spill file (SpillTo), the records
// older than the newest `keep_in_memory` are written to it in batches and read back on demand,
// so that the process's memory and its saved state (the journal snapshot) stay bounded however
// long the robot runs. Only lookups of old times touch the file: a factor onto the frozen past
// (a loop closure seen by the RBPF-SLAM), the whole trajectory at the end of a run, a restore's
// checks.
//
// THE FILE: a 16-byte header ("FLRETIRE", version, record size), then the records, fixed size,
// in this machine's byte order (it never leaves the robot). A saved state (SaveState) holds the
// in-memory records and how many of the file's are its own, with the newest spilled stamp; a
// loader bound to the same file checks that the file still holds them and adopts them. Records
// after them (written after that snapshot, before a crash) are overwritten as the restore's
// replay retires the same nodes again: the file is cut at the first write of a new or restored
// trajectory, never when it is opened (a restore needs it).
//
// ERRORS: a spill that cannot be written (disk full, a removed folder) keeps the records in
// memory, nothing is lost, and is reported by spill_error() (tried again every batch). A spilled
// record that cannot be read back (someone truncated the file) throws std::runtime_error naming
// the file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <string>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/state_buffer.hpp"
#include "fusionloc/common/time.hpp"

namespace fl::fusion {

struct RetiredRecord {
  Utime utime = 0;
  Pose2 T_map_base;        // fused, frozen
  Pose2 T_map_base_rbpf;   // the RBPF's input pose (interpolation of late factor times)
  Utime anchor_utime = 0;  // the map node it is kept as or merged into
};

// The spill file of one process, shared by the fusion objects it makes in turn (a reset, a
// journal restore). Opening never reads or removes records.
class RetiredSpillFile {
 public:
  static constexpr size_t kHeaderBytes = 16;
  static constexpr size_t kRecordBytes = 64;
  // Opens PATH, creating it if needed. Throws std::runtime_error naming PATH if it cannot be
  // opened, or if it is not empty and does not start with this format's header.
  explicit RetiredSpillFile(std::string path);
  ~RetiredSpillFile();
  RetiredSpillFile(const RetiredSpillFile&) = delete;
  RetiredSpillFile& operator=(const RetiredSpillFile&) = delete;

  const std::string& path() const { return path_; }
  // Whole records in the file now.
  size_t RecordsOnDisk() const;
  // Writes records [first, first + n) (first <= RecordsOnDisk()); `cut` also drops every record
  // after them. Throws std::runtime_error (with errno's text) on failure.
  void Write(size_t first, const RetiredRecord* records, size_t n, bool cut);
  // Reads records [first, first + n); throws std::runtime_error if they are not all there.
  void Read(size_t first, RetiredRecord* out, size_t n) const;

 private:
  std::string path_;
  int fd_ = -1;
};

class RetiredTrajectory {
 public:
  static constexpr size_t kDefaultKeepInMemory = 6000;  // 10 minutes of scans at 10 Hz
  static constexpr size_t kDefaultSpillBatch = 1000;    // records per write

  // Spills records older than the newest keep_in_memory (>= 1) into `file`, `batch` (>= 1) at a
  // time (file nullptr: keep all in memory). Only while empty (std::logic_error otherwise).
  void SpillTo(std::shared_ptr<RetiredSpillFile> file,
               size_t keep_in_memory = kDefaultKeepInMemory, size_t batch = kDefaultSpillBatch);
  const std::shared_ptr<RetiredSpillFile>& spill_file() const { return file_; }
  size_t keep_in_memory() const { return keep_in_memory_; }
  size_t spill_batch() const { return batch_; }

  size_t size() const { return spilled_ + memory_.size(); }
  bool empty() const { return size() == 0; }
  size_t spilled() const { return spilled_; }
  size_t in_memory() const { return memory_.size(); }
  // Record k (0 = oldest); from the file if it was spilled.
  RetiredRecord at(size_t k) const;
  const RetiredRecord& back() const { return memory_.back(); }  // always in memory
  Utime front_utime() const { return front_utime_; }             // the oldest record's
  // Appends (its utime must be after back()'s; std::invalid_argument otherwise).
  void push_back(const RetiredRecord& record);
  // First index whose utime is >= t (size() if none).
  size_t LowerBound(Utime t) const;
  // Calls fn on records [first, size()) in order (the spilled ones read in batches).
  void ForEach(size_t first, const std::function<void(const RetiredRecord&)>& fn) const;
  // The last spill failure ("" if the last spill worked or none was needed).
  const std::string& spill_error() const { return spill_error_; }

  // Saved state: the spilled count and newest spilled stamp, then the in-memory records.
  void SaveState(StateWriter* w) const;
  // Into an empty trajectory bound (SpillTo) as the saver's was. Throws StateError (through
  // `r`) if the records are out of order or not finite, or if the state has spilled records
  // that this trajectory's file does not hold (no file, another file, a shorter one).
  void LoadState(StateReader* r);

 private:
  void Spill();

  std::shared_ptr<RetiredSpillFile> file_;
  size_t keep_in_memory_ = kDefaultKeepInMemory;
  size_t batch_ = kDefaultSpillBatch;
  size_t spilled_ = 0;                // records [0, spilled_) are in the file
  std::deque<RetiredRecord> memory_;  // records [spilled_, size())
  Utime last_spilled_utime_ = 0;
  Utime front_utime_ = 0;
  bool file_cut_ = false;  // the file's stale tail is cut (at this trajectory's first write)
  std::string spill_error_;
};

}  // namespace fl::fusion

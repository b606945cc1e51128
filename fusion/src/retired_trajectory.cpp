#include "fusionloc/fusion/retired_trajectory.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <vector>

namespace fl::fusion {
namespace {

constexpr char kMagic[8] = {'F', 'L', 'R', 'E', 'T', 'I', 'R', 'E'};
constexpr uint32_t kVersion = 1;
constexpr size_t kRecord = RetiredSpillFile::kRecordBytes;
constexpr size_t kHeader = RetiredSpillFile::kHeaderBytes;
static_assert(sizeof(Utime) == 8 && sizeof(double) == 8, "the record layout needs 8-byte fields");

void Header(uint8_t out[kHeader]) {
  std::memcpy(out, kMagic, 8);
  const uint32_t version = kVersion, record = static_cast<uint32_t>(kRecord);
  std::memcpy(out + 8, &version, 4);
  std::memcpy(out + 12, &record, 4);
}

void Encode(const RetiredRecord& r, uint8_t* out) {
  const double v[6] = {r.T_map_base.x,      r.T_map_base.y,      r.T_map_base.theta,
                       r.T_map_base_rbpf.x, r.T_map_base_rbpf.y, r.T_map_base_rbpf.theta};
  std::memcpy(out, &r.utime, 8);
  std::memcpy(out + 8, v, 48);
  std::memcpy(out + 56, &r.anchor_utime, 8);
}

RetiredRecord Decode(const uint8_t* in) {
  RetiredRecord r;
  double v[6];
  std::memcpy(&r.utime, in, 8);
  std::memcpy(v, in + 8, 48);
  std::memcpy(&r.anchor_utime, in + 56, 8);
  r.T_map_base = Pose2(v[0], v[1], v[2]);
  r.T_map_base_rbpf = Pose2(v[3], v[4], v[5]);
  return r;
}

bool Finite(const Pose2& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.theta);
}

std::string Errno() { return std::strerror(errno); }

}  // namespace

RetiredSpillFile::RetiredSpillFile(std::string path) : path_(std::move(path)) {
  fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) {
    throw std::runtime_error("retired trajectory file " + path_ + ": cannot open (" + Errno() +
                             ")");
  }
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd_);
    throw std::runtime_error("retired trajectory file " + path_ + ": not a regular file");
  }
  uint8_t want[kHeader], have[kHeader];
  Header(want);
  if (st.st_size == 0) {
    if (::pwrite(fd_, want, kHeader, 0) != static_cast<ssize_t>(kHeader)) {
      const std::string why = Errno();
      ::close(fd_);
      throw std::runtime_error("retired trajectory file " + path_ + ": cannot write (" + why +
                               ")");
    }
    return;
  }
  if (st.st_size < static_cast<off_t>(kHeader) ||
      ::pread(fd_, have, kHeader, 0) != static_cast<ssize_t>(kHeader) ||
      std::memcmp(have, want, kHeader) != 0) {
    ::close(fd_);
    throw std::runtime_error("retired trajectory file " + path_ +
                             ": not one this version of fl-fusion wrote (no FLRETIRE header of "
                             "version 1); move it away or remove it");
  }
}

RetiredSpillFile::~RetiredSpillFile() {
  if (fd_ >= 0) ::close(fd_);
}

size_t RetiredSpillFile::RecordsOnDisk() const {
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || st.st_size < static_cast<off_t>(kHeader)) return 0;
  return (static_cast<size_t>(st.st_size) - kHeader) / kRecord;
}

void RetiredSpillFile::Write(size_t first, const RetiredRecord* records, size_t n, bool cut) {
  std::vector<uint8_t> bytes(n * kRecord);
  for (size_t k = 0; k < n; ++k) Encode(records[k], bytes.data() + k * kRecord);
  const off_t offset = static_cast<off_t>(kHeader + first * kRecord);
  if (cut && ::ftruncate(fd_, offset) != 0) {
    throw std::runtime_error("retired trajectory file " + path_ + ": cannot cut (" + Errno() +
                             ")");
  }
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t w = ::pwrite(fd_, bytes.data() + done, bytes.size() - done,
                               offset + static_cast<off_t>(done));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) {
      const std::string why = w < 0 ? Errno() : "nothing written";
      // Leave no partial record behind: the file ends where the records written so far end.
      // (If even that fails, what lies past `offset` is not counted by the trajectory.)
      const int cut_result = ::ftruncate(fd_, offset);
      static_cast<void>(cut_result);
      throw std::runtime_error("retired trajectory file " + path_ + ": cannot write (" + why +
                               ")");
    }
    done += static_cast<size_t>(w);
  }
}

void RetiredSpillFile::Read(size_t first, RetiredRecord* out, size_t n) const {
  std::vector<uint8_t> bytes(n * kRecord);
  const off_t offset = static_cast<off_t>(kHeader + first * kRecord);
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t r = ::pread(fd_, bytes.data() + done, bytes.size() - done,
                              offset + static_cast<off_t>(done));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) {
      throw std::runtime_error("retired trajectory file " + path_ + ": records " +
                               std::to_string(first) + " to " + std::to_string(first + n - 1) +
                               " cannot be read (" + (r < 0 ? Errno() : "the file is shorter") +
                               "); was it changed by another program?");
    }
    done += static_cast<size_t>(r);
  }
  for (size_t k = 0; k < n; ++k) out[k] = Decode(bytes.data() + k * kRecord);
}

void RetiredTrajectory::SpillTo(std::shared_ptr<RetiredSpillFile> file, size_t keep_in_memory,
                                size_t batch) {
  if (!empty()) throw std::logic_error("RetiredTrajectory::SpillTo on a non-empty trajectory");
  if (keep_in_memory < 1 || batch < 1) {
    throw std::invalid_argument("RetiredTrajectory: keep_in_memory and batch must be >= 1");
  }
  file_ = std::move(file);
  keep_in_memory_ = keep_in_memory;
  batch_ = batch;
  file_cut_ = false;
}

RetiredRecord RetiredTrajectory::at(size_t k) const {
  if (k >= size()) throw std::out_of_range("RetiredTrajectory::at");
  if (k >= spilled_) return memory_[k - spilled_];
  RetiredRecord r;
  file_->Read(k, &r, 1);
  return r;
}

void RetiredTrajectory::push_back(const RetiredRecord& record) {
  if (!empty() && record.utime <= back().utime) {
    throw std::invalid_argument("RetiredTrajectory: records must be appended in time order");
  }
  if (empty()) front_utime_ = record.utime;
  memory_.push_back(record);
  // Spill when a whole batch is beyond what is kept; after a failure, again a batch later.
  if (file_ && memory_.size() >= keep_in_memory_ + batch_ &&
      (memory_.size() - keep_in_memory_) % batch_ == 0) {
    Spill();
  }
}

void RetiredTrajectory::Spill() {
  const size_t n = memory_.size() - keep_in_memory_;
  std::vector<RetiredRecord> batch(memory_.begin(), memory_.begin() + static_cast<long>(n));
  try {
    file_->Write(spilled_, batch.data(), n, /*cut=*/!file_cut_);
  } catch (const std::exception& e) {
    spill_error_ = std::string(e.what()) + "; " + std::to_string(memory_.size()) +
                   " retired poses kept in memory";
    return;
  }
  file_cut_ = true;
  spill_error_.clear();
  spilled_ += n;
  last_spilled_utime_ = batch.back().utime;
  memory_.erase(memory_.begin(), memory_.begin() + static_cast<long>(n));
}

size_t RetiredTrajectory::LowerBound(Utime t) const {
  const auto in_memory =
      std::lower_bound(memory_.begin(), memory_.end(), t,
                       [](const RetiredRecord& r, Utime time) { return r.utime < time; });
  if (in_memory != memory_.begin() || spilled_ == 0 || t > last_spilled_utime_) {
    return spilled_ + static_cast<size_t>(in_memory - memory_.begin());
  }
  size_t lo = 0, hi = spilled_;  // the answer is in [0, spilled_]
  while (lo < hi) {
    const size_t mid = lo + (hi - lo) / 2;
    if (at(mid).utime < t)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

void RetiredTrajectory::ForEach(size_t first,
                                const std::function<void(const RetiredRecord&)>& fn) const {
  std::vector<RetiredRecord> batch;
  for (size_t k = first; k < spilled_;) {
    const size_t n = std::min(kDefaultSpillBatch, spilled_ - k);
    batch.resize(n);
    file_->Read(k, batch.data(), n);
    for (const RetiredRecord& r : batch) fn(r);
    k += n;
  }
  for (size_t k = std::max(first, spilled_) - spilled_; k < memory_.size(); ++k) fn(memory_[k]);
}

void RetiredTrajectory::SaveState(StateWriter* w) const {
  w->PutCount(spilled_);
  w->Put(last_spilled_utime_);
  w->PutCount(memory_.size());
  for (const RetiredRecord& r : memory_) {
    w->Put(r.utime);
    w->Put(r.T_map_base);
    w->Put(r.T_map_base_rbpf);
    w->Put(r.anchor_utime);
  }
}

void RetiredTrajectory::LoadState(StateReader* r) {
  if (!empty()) throw std::logic_error("RetiredTrajectory::LoadState on a non-empty trajectory");
  const auto spilled = static_cast<size_t>(r->Get<uint64_t>("retired.spilled"));
  const Utime last_spilled_utime = r->Get<int64_t>("retired.last_spilled_utime");
  if (spilled > 0) {
    if (!file_) {
      r->Fail("its retired trajectory has " + std::to_string(spilled) +
              " poses in a spill file, and this fusion has none (a journal of a run with "
              "--journal, restored without it?)");
    }
    const size_t on_disk = file_->RecordsOnDisk();
    if (on_disk < spilled) {
      r->Fail("its retired trajectory has " + std::to_string(spilled) + " poses in " +
              file_->path() + ", which holds " + std::to_string(on_disk));
    }
    RetiredRecord newest;
    file_->Read(spilled - 1, &newest, 1);
    if (newest.utime != last_spilled_utime) {
      r->Fail(file_->path() + " is not the retired trajectory of this state (its pose " +
              std::to_string(spilled - 1) + " is at utime " + std::to_string(newest.utime) +
              ", the state's at " + std::to_string(last_spilled_utime) + ")");
    }
  }
  constexpr size_t kSavedRecordBytes = 8 + 6 * 8 + 8;
  const size_t n = r->Count(kSavedRecordBytes, "retired nodes");
  std::deque<RetiredRecord> memory;
  for (size_t k = 0; k < n; ++k) {
    RetiredRecord rec;
    rec.utime = r->Get<int64_t>("retired.utime");
    rec.T_map_base = r->GetPose2("retired.T_map_base");
    rec.T_map_base_rbpf = r->GetPose2("retired.T_map_base_rbpf");
    rec.anchor_utime = r->Get<int64_t>("retired.anchor_utime");
    if (!Finite(rec.T_map_base) || !Finite(rec.T_map_base_rbpf)) {
      r->Fail("retired node " + std::to_string(spilled + k) + ": its pose is not finite");
    }
    const Utime previous = !memory.empty() ? memory.back().utime
                                           : (spilled > 0 ? last_spilled_utime : INT64_MIN);
    if (rec.utime <= previous) {
      r->Fail("retired node " + std::to_string(spilled + k) + " is not after the previous one");
    }
    memory.push_back(rec);
  }
  if (spilled > 0 && memory.empty()) {
    r->Fail("its retired trajectory has spilled poses but none in memory (the newest is kept)");
  }
  RetiredRecord oldest;
  if (spilled > 0) {
    file_->Read(0, &oldest, 1);
  } else if (!memory.empty()) {
    oldest = memory.front();
  }
  front_utime_ = oldest.utime;
  spilled_ = spilled;
  last_spilled_utime_ = last_spilled_utime;
  memory_ = std::move(memory);
  file_cut_ = false;  // what the file holds after `spilled` is cut at the next write
  spill_error_.clear();
}

}  // namespace fl::fusion

#include "fusionloc/fusion/retired_trajectory.hpp"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "test_paths.hpp"

namespace fl::fusion {
namespace {

using fl::test::TempDir;

// Record k of a synthetic trajectory: 10 Hz, distinct values in every field.
RetiredRecord MakeRecord(size_t k, double offset = 0.0) {
  const double s = static_cast<double>(k);
  RetiredRecord r;
  r.utime = 1'000'000 + static_cast<Utime>(k) * 100'000;
  r.T_map_base = Pose2(0.1 * s + offset, -0.05 * s, 0.001 * s);
  r.T_map_base_rbpf = Pose2(0.1 * s + 0.01, -0.05 * s + 0.02, 0.001 * s + 0.003);
  r.anchor_utime = 1'000'000 + static_cast<Utime>(k / 10) * 1'000'000;
  return r;
}

void ExpectSame(const RetiredRecord& a, const RetiredRecord& b, size_t k) {
  EXPECT_EQ(a.utime, b.utime) << k;
  EXPECT_EQ(a.T_map_base.x, b.T_map_base.x) << k;
  EXPECT_EQ(a.T_map_base.y, b.T_map_base.y) << k;
  EXPECT_EQ(a.T_map_base.theta, b.T_map_base.theta) << k;
  EXPECT_EQ(a.T_map_base_rbpf.x, b.T_map_base_rbpf.x) << k;
  EXPECT_EQ(a.T_map_base_rbpf.theta, b.T_map_base_rbpf.theta) << k;
  EXPECT_EQ(a.anchor_utime, b.anchor_utime) << k;
}

// Every way of reading `t` gives records [0, n) of MakeRecord(., offset).
void ExpectHolds(const RetiredTrajectory& t, size_t n, double offset = 0.0) {
  ASSERT_EQ(t.size(), n);
  for (size_t k = 0; k < n; ++k) ExpectSame(t.at(k), MakeRecord(k, offset), k);
  for (size_t first : {size_t{0}, size_t{1}, n / 3, n - 1, n}) {
    size_t k = first;
    t.ForEach(first, [&](const RetiredRecord& r) {
      ExpectSame(r, MakeRecord(k, offset), k);
      ++k;
    });
    EXPECT_EQ(k, n) << "ForEach from " << first;
  }
  EXPECT_EQ(t.front_utime(), MakeRecord(0).utime);
  // LowerBound: exact stamps, stamps between records, before the first and after the last.
  for (size_t k = 0; k < n; k += 7) {
    EXPECT_EQ(t.LowerBound(MakeRecord(k).utime), k);
    EXPECT_EQ(t.LowerBound(MakeRecord(k).utime - 1), k);
    EXPECT_EQ(t.LowerBound(MakeRecord(k).utime + 1), k + 1);
  }
  EXPECT_EQ(t.LowerBound(0), 0u);
  EXPECT_EQ(t.LowerBound(MakeRecord(n - 1).utime + 1), n);
}

// Records [0, n) into `t`, spilling all but the newest 50 into a file at `path`.
void FillSpilling(RetiredTrajectory* t, const std::string& path, size_t n) {
  t->SpillTo(std::make_shared<RetiredSpillFile>(path), 50);
  for (size_t k = 0; k < n; ++k) t->push_back(MakeRecord(k));
}

std::vector<uint8_t> Save(const RetiredTrajectory& t) {
  StateWriter w;
  t.SaveState(&w);
  return w.Release();
}

TEST(RetiredTrajectory, InMemoryWithoutAFile) {
  RetiredTrajectory t;
  for (size_t k = 0; k < 2500; ++k) t.push_back(MakeRecord(k));
  EXPECT_EQ(t.spilled(), 0u);
  EXPECT_EQ(t.in_memory(), 2500u);
  ExpectHolds(t, 2500);
  EXPECT_THROW(t.push_back(MakeRecord(10)), std::invalid_argument);  // not after the newest
  const std::vector<uint8_t> bytes = Save(t);
  RetiredTrajectory loaded;
  StateReader r(bytes.data(), bytes.size());
  loaded.LoadState(&r);
  EXPECT_TRUE(r.at_end());
  ExpectHolds(loaded, 2500);
}

TEST(RetiredTrajectory, OlderRecordsGoToTheFileAndReadBackTheSame) {
  TempDir dir;
  auto file = std::make_shared<RetiredSpillFile>(dir.file("j.retired"));
  RetiredTrajectory t;
  t.SpillTo(file, /*keep_in_memory=*/50);
  const size_t n = 3 * RetiredTrajectory::kDefaultSpillBatch + 321;
  size_t most_in_memory = 0;
  for (size_t k = 0; k < n; ++k) {
    t.push_back(MakeRecord(k));
    most_in_memory = std::max(most_in_memory, t.in_memory());
  }
  EXPECT_EQ(t.spilled(), 3 * RetiredTrajectory::kDefaultSpillBatch);
  EXPECT_EQ(file->RecordsOnDisk(), t.spilled());
  EXPECT_LT(most_in_memory, 50 + RetiredTrajectory::kDefaultSpillBatch);  // bounded
  EXPECT_TRUE(t.spill_error().empty());
  ExpectHolds(t, n);
  EXPECT_EQ(std::filesystem::file_size(dir.file("j.retired")),
            RetiredSpillFile::kHeaderBytes + t.spilled() * RetiredSpillFile::kRecordBytes);
  // The saved state holds the records in memory only.
  EXPECT_LT(Save(t).size(), (t.in_memory() + 1) * RetiredSpillFile::kRecordBytes + 64);
}

TEST(RetiredTrajectory, ARestoreAdoptsTheFileAndReplacesWhatCameAfterItsSnapshot) {
  TempDir dir;
  const std::string path = dir.file("j.retired");
  auto file = std::make_shared<RetiredSpillFile>(path);
  RetiredTrajectory original;
  original.SpillTo(file, 50);
  const size_t at_snapshot = 2 * RetiredTrajectory::kDefaultSpillBatch + 100;
  for (size_t k = 0; k < at_snapshot; ++k) original.push_back(MakeRecord(k));
  const std::vector<uint8_t> snapshot = Save(original);
  // The run goes on past the snapshot (and spills more) before it is killed.
  for (size_t k = at_snapshot; k < 4000; ++k) original.push_back(MakeRecord(k));
  ASSERT_GT(file->RecordsOnDisk(), 2 * RetiredTrajectory::kDefaultSpillBatch);
  const size_t on_disk_at_kill = file->RecordsOnDisk();

  // The respawn opens the same file (nothing removed by opening) and loads the snapshot.
  auto reopened = std::make_shared<RetiredSpillFile>(path);
  EXPECT_EQ(reopened->RecordsOnDisk(), on_disk_at_kill);
  RetiredTrajectory restored;
  restored.SpillTo(reopened, 50);
  StateReader r(snapshot.data(), snapshot.size());
  restored.LoadState(&r);
  ExpectHolds(restored, at_snapshot);
  // Its replay retires other poses than the killed run did after the snapshot: they replace
  // the stale records, none of which is read again.
  for (size_t k = at_snapshot; k < 4200; ++k) {
    RetiredRecord rec = MakeRecord(k);
    rec.T_map_base.x += 1.0;
    restored.push_back(rec);
  }
  EXPECT_EQ(reopened->RecordsOnDisk(), restored.spilled());
  for (size_t k = 0; k < 4200; ++k) {
    ExpectSame(restored.at(k), k < at_snapshot ? MakeRecord(k) : [&] {
      RetiredRecord rec = MakeRecord(k);
      rec.T_map_base.x += 1.0;
      return rec;
    }(), k);
  }
}

TEST(RetiredTrajectory, AStateWhoseRecordsTheFileDoesNotHoldIsRefused) {
  TempDir dir;
  const std::string path = dir.file("j.retired");
  RetiredTrajectory original;
  FillSpilling(&original, path, 1500);
  ASSERT_EQ(original.spilled(), RetiredTrajectory::kDefaultSpillBatch);
  const std::vector<uint8_t> snapshot = Save(original);
  auto expect_refused = [&](RetiredTrajectory* t, const std::string& words) {
    StateReader r(snapshot.data(), snapshot.size());
    try {
      t->LoadState(&r);
      FAIL() << "loaded; expected an error with '" << words << "'";
    } catch (const StateError& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
    EXPECT_TRUE(t->empty());
  };
  // No file bound.
  RetiredTrajectory unbound;
  expect_refused(&unbound, "this fusion has none");
  // Another run's file (the same count, other stamps).
  RetiredTrajectory other_run;
  other_run.SpillTo(std::make_shared<RetiredSpillFile>(dir.file("other.retired")), 50);
  for (size_t k = 0; k < 1500; ++k) {
    RetiredRecord rec = MakeRecord(k);
    rec.utime += 7;
    other_run.push_back(rec);
  }
  RetiredTrajectory wrong;
  wrong.SpillTo(std::make_shared<RetiredSpillFile>(dir.file("other.retired")), 50);
  expect_refused(&wrong, "is not the retired trajectory of this state");
  // The file cut short.
  std::filesystem::resize_file(path, RetiredSpillFile::kHeaderBytes +
                                         500 * RetiredSpillFile::kRecordBytes);
  RetiredTrajectory short_file;
  short_file.SpillTo(std::make_shared<RetiredSpillFile>(path), 50);
  expect_refused(&short_file, "which holds 500");
}

TEST(RetiredTrajectory, AFileOfAnotherFormatIsNotOpenedNorChanged) {
  TempDir dir;
  const std::string path = dir.file("notes.retired");
  { std::ofstream(path) << "not a retired trajectory\n"; }
  try {
    RetiredSpillFile file(path);
    FAIL() << "opened";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("move it away"), std::string::npos) << e.what();
  }
  EXPECT_EQ(std::filesystem::file_size(path), 25u);
  EXPECT_THROW(RetiredSpillFile(dir.file("no/such/folder/j.retired")), std::runtime_error);
}

TEST(RetiredTrajectory, AFailedSpillKeepsTheRecordsInMemoryAndTriesAgain) {
  TempDir dir;
  const std::string path = dir.file("j.retired");
  RetiredTrajectory t;
  FillSpilling(&t, path, 1100);
  ASSERT_EQ(t.spilled(), RetiredTrajectory::kDefaultSpillBatch);
  // A full disk: the file may not grow past its size now (EFBIG instead of SIGXFSZ).
  const auto previous_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit previous{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &previous), 0);
  rlimit limit = previous;
  limit.rlim_cur = std::filesystem::file_size(path);
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limit), 0);
  for (size_t k = 1100; k < 2100; ++k) t.push_back(MakeRecord(k));
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &previous), 0);
  std::signal(SIGXFSZ, previous_handler);
  EXPECT_EQ(t.spilled(), RetiredTrajectory::kDefaultSpillBatch);  // the second batch was refused
  EXPECT_NE(t.spill_error().find("cannot write"), std::string::npos) << t.spill_error();
  EXPECT_NE(t.spill_error().find(path), std::string::npos) << t.spill_error();
  ExpectHolds(t, 2100);  // nothing lost
  // Room again: the next batch spills everything due.
  for (size_t k = 2100; k < 3100; ++k) t.push_back(MakeRecord(k));
  EXPECT_TRUE(t.spill_error().empty()) << t.spill_error();
  EXPECT_EQ(t.spilled(), 3000u);
  EXPECT_EQ(t.in_memory(), 100u);
  ExpectHolds(t, 3100);
}

}  // namespace
}  // namespace fl::fusion

// LcmLogWriter on a device that fails: every write error is reported (the file and the
// reason), and a log whose writing failed is never renamed into place as if it were whole.
// (Write and read round trips are in lcm_interface_test.cpp.)
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>

#include <filesystem>
#include <string>
#include <vector>

#include "fusionloc/common/lcm_interface.hpp"
#include "test_paths.hpp"

namespace fl {
namespace {

namespace fs = std::filesystem;

bool IsCharDevice(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISCHR(st.st_mode);
}

// Writes events of `size` bytes until one throws (or `max_events` were written); returns the
// message of what was thrown ("" if nothing was).
std::string WriteUntilError(LcmLogWriter* w, int size, int max_events) {
  const std::vector<uint8_t> data(static_cast<size_t>(size), 0x5a);
  try {
    for (int i = 0; i < max_events; ++i) w->Write("LASER", data.data(), size, 1000 + i);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

TEST(LcmLogWriter, WriteOnAFullDeviceThrowsNamingTheFileAndTheReason) {
  ASSERT_TRUE(IsCharDevice("/dev/full")) << "this test needs /dev/full";
  {
    LcmLogWriter w("/dev/full", /*atomic=*/false);
    // More than any stdio buffer: a write reaches the device and fails within these.
    const std::string error = WriteUntilError(&w, 10000, 100);
    EXPECT_NE(error.find("/dev/full"), std::string::npos) << error;
    EXPECT_NE(error.find("No space left on device"), std::string::npos) << error;
    // Once failed, the writer refuses to go on (no hole in the middle of a log).
    EXPECT_THROW(w.Write("LASER", "abc", 3, 0), std::runtime_error);
    EXPECT_THROW(w.Flush(), std::runtime_error);
    EXPECT_THROW(w.Close(), std::runtime_error);
  }
  EXPECT_TRUE(IsCharDevice("/dev/full")) << "a failed close must never delete a device";
}

TEST(LcmLogWriter, FlushOnAFullDeviceThrows) {
  ASSERT_TRUE(IsCharDevice("/dev/full")) << "this test needs /dev/full";
  {
    LcmLogWriter w("/dev/full", /*atomic=*/false);
    w.Write("LASER", "abc", 3, 0);  // small: stays in the buffer
    try {
      w.Flush();
      ADD_FAILURE() << "Flush on /dev/full did not throw";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("No space left on device"), std::string::npos)
          << e.what();
    }
    // The destructor closes without throwing and without deleting the device.
  }
  EXPECT_TRUE(IsCharDevice("/dev/full"));
}

// The partial file is a link to /dev/full: every write to it fails, as on a full disk.
TEST(LcmLogWriter, AFailedLogIsNeverRenamedIntoPlace) {
  ASSERT_TRUE(IsCharDevice("/dev/full")) << "this test needs /dev/full";
  test::TempDir dir;
  const std::string path = dir.file("run.lcmlog");
  {
    fs::create_symlink("/dev/full", path + ".partial");
    LcmLogWriter w(path);
    w.Write("LASER", "abc", 3, 0);
    EXPECT_THROW(w.Flush(), std::runtime_error);
    try {
      w.Close();
      ADD_FAILURE() << "Close after a failed write did not throw";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("not renamed to '" + path + "'"), std::string::npos)
          << e.what();
    }
  }
  EXPECT_FALSE(fs::exists(path));
  // The same when the writer is only destroyed (as while an exception unwinds).
  fs::remove(path + ".partial");
  {
    fs::create_symlink("/dev/full", path + ".partial");
    LcmLogWriter w(path);
    EXPECT_NE(WriteUntilError(&w, 10000, 100), "");
  }
  EXPECT_FALSE(fs::exists(path));
  EXPECT_TRUE(IsCharDevice("/dev/full"));
}

// A real short write on a regular file: the file size limit (RLIMIT_FSIZE, EFBIG) stands in
// for a full disk. The partial file keeps the events written before the error, is not
// renamed, and Abandon() still deletes it after the failed Close().
TEST(LcmLogWriter, ShortWriteOnARegularFileKeepsThePartialUntilAbandoned) {
  test::TempDir dir;
  const std::string path = dir.file("run.lcmlog");
  struct rlimit old {};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  LcmLogWriter w(path);
  std::string error;
  {
    const auto old_handler = signal(SIGXFSZ, SIG_IGN);
    struct rlimit small = old;
    small.rlim_cur = 20000;
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
    error = WriteUntilError(&w, 1000, 100);
    setrlimit(RLIMIT_FSIZE, &old);
    signal(SIGXFSZ, old_handler);
  }
  EXPECT_NE(error.find(path + ".partial"), std::string::npos) << error;
  EXPECT_NE(error.find("File too large"), std::string::npos) << error;
  EXPECT_THROW(w.Close(), std::runtime_error);
  EXPECT_FALSE(fs::exists(path));
  ASSERT_TRUE(fs::is_regular_file(path + ".partial"));
  EXPECT_EQ(fs::file_size(path + ".partial"), 20000u);
  {
    // What was written before the error reads back: whole events, then a cut-short one.
    LcmLogReader r(path + ".partial");
    LcmLogEvent e;
    int n = 0;
    while (r.Next(&e)) {
      EXPECT_EQ(e.utime, 1000 + n);
      EXPECT_EQ(e.data.size(), 1000u);
      ++n;
    }
    EXPECT_EQ(n, 20000 / (28 + 5 + 1000));
    EXPECT_TRUE(r.truncated());
  }
  w.Abandon();
  EXPECT_FALSE(fs::exists(path + ".partial"));
  EXPECT_FALSE(fs::exists(path));
}

}  // namespace
}  // namespace fl

// Inputs from the network are bounded (issue 27, docs/RELIABILITY.md): a message claiming a
// huge array or string is refused before anything of that size is allocated. LCM 1.3.1's
// generated decoders resize first and check after; lcmtypes/patch_decode.cmake fixes ours
// (fusionloc_lcm_guard.hpp). This binary replaces operator new to record the largest request.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <new>
#include <vector>

// GCC 12's maybe-uninitialized false positive inside lcm-gen's decode() once it is inlined
// (as in procman/lcm/include/fusionloc/procman/bot_procman_types.hpp).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include "bot_core/images_t.hpp"
#include "bot_core/planar_lidar_t.hpp"
#include "fusionloc/occupancy_grid_t.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/status_t.hpp"
#pragma GCC diagnostic pop
#include "fusionloc/common/lcm_interface.hpp"

namespace {
std::atomic<size_t> g_largest{0};
}  // namespace

// The replacement allocates with malloc and frees with free, which GCC cannot tell from
// mixing new and free once it inlines them.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(size_t size) {
  size_t seen = g_largest.load();
  while (size > seen && !g_largest.compare_exchange_weak(seen, size)) {
  }
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, size_t) noexcept { std::free(p); }

namespace {

// Big-endian writers for hand-made messages (LCM's wire format).
struct Wire {
  std::vector<uint8_t> b;
  Wire& I64(int64_t v) {
    for (int i = 7; i >= 0; --i) b.push_back(static_cast<uint8_t>(static_cast<uint64_t>(v) >> (8 * i)));
    return *this;
  }
  Wire& I32(int32_t v) {
    for (int i = 3; i >= 0; --i) b.push_back(static_cast<uint8_t>(static_cast<uint32_t>(v) >> (8 * i)));
    return *this;
  }
  Wire& Raw(const char* s, size_t n) {
    b.insert(b.end(), s, s + n);
    return *this;
  }
  int size() const { return static_cast<int>(b.size()); }
};

template <class T>
int DecodeCounting(const Wire& w, size_t* largest) {
  T msg;
  g_largest = 0;
  const int r = msg.decode(w.b.data(), 0, w.size());
  *largest = g_largest.load();
  return r;
}

// planar_lidar_t: utime, nranges, ranges[], nintensities, intensities[], rad0, radstep.
Wire Lidar(int32_t nranges) {
  Wire w;
  w.I64(bot_core::planar_lidar_t::getHash()).I64(1).I32(nranges);
  for (int i = 0; i < 4; ++i) w.I32(0x3f800000);  // four 1.0f, whatever nranges claims
  return w.I32(0).I32(0).I32(0);
}

TEST(LcmDecodeBounds, HugeArrayCountIsRefusedBeforeAllocating) {
  for (const int32_t n : {2147483647, 1 << 30, 1 << 20, 5}) {
    size_t largest = 0;
    EXPECT_LT(DecodeCounting<bot_core::planar_lidar_t>(Lidar(n), &largest), 0) << n;
    EXPECT_LT(largest, 1024u) << "claimed " << n << " ranges";
  }
  size_t largest = 0;
  EXPECT_EQ(DecodeCounting<bot_core::planar_lidar_t>(Lidar(4), &largest), Lidar(4).size());
}

TEST(LcmDecodeBounds, NegativeCountIsRefusedNotThrown) {
  size_t largest = 0;
  EXPECT_LT(DecodeCounting<bot_core::planar_lidar_t>(Lidar(-1), &largest), 0);
  EXPECT_LT(DecodeCounting<bot_core::planar_lidar_t>(Lidar(-2147483647 - 1), &largest), 0);
}

TEST(LcmDecodeBounds, CountsOfMessagesAndStringsAreBoundedToo) {
  // images_t: utime, n_images, image_types[n] (int16), images[n].
  Wire images;
  images.I64(bot_core::images_t::getHash()).I64(1).I32(1 << 28).I32(0).I32(0);
  size_t largest = 0;
  EXPECT_LT(DecodeCounting<bot_core::images_t>(images, &largest), 0);
  EXPECT_LT(largest, 1024u);
  // occupancy_grid_t: utime, resolution, width, height, origin_x, origin_y, num_cells, cells.
  Wire grid;
  grid.I64(fusionloc::occupancy_grid_t::getHash()).I64(1).I64(0).I32(65536).I32(65536);
  grid.I64(0).I64(0).I32(2147483647).I32(0);
  EXPECT_LT(DecodeCounting<fusionloc::occupancy_grid_t>(grid, &largest), 0);
  EXPECT_LT(largest, 1024u);
  // point_cloud_t: frame string, then num_points rows of 3 floats.
  Wire cloud;
  cloud.I64(fusionloc::point_cloud_t::getHash()).I64(1).I32(7).Raw("camera", 7).I32(1 << 29);
  cloud.I32(0).I32(0).I32(0).I32(0);
  EXPECT_LT(DecodeCounting<fusionloc::point_cloud_t>(cloud, &largest), 0);
  EXPECT_LT(largest, 1024u);
}

// status_t starts utime, process (string), ...: a string's length must be >= 1 (its NUL) and
// fit in the message, and it may not hold a NUL of its own (the encoder would write less
// than getEncodedSize() says).
TEST(LcmDecodeBounds, BadStringLengthsAreRefused) {
  for (const int32_t len : {0, -1, -2147483647 - 1, 1 << 30}) {
    Wire w;
    w.I64(fusionloc::status_t::getHash()).I64(1).I32(len).Raw("abc", 4);
    size_t largest = 0;
    EXPECT_LT(DecodeCounting<fusionloc::status_t>(w, &largest), 0) << len;
    EXPECT_LT(largest, 1024u) << len;
  }
  fusionloc::status_t ok{};
  ok.process = "fl-x";
  ok.message = "fine";
  std::vector<uint8_t> bytes(static_cast<size_t>(ok.getEncodedSize()));
  ok.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  fusionloc::status_t back;
  EXPECT_EQ(back.decode(bytes.data(), 0, static_cast<int>(bytes.size())),
            static_cast<int>(bytes.size()));
  EXPECT_EQ(back.process, "fl-x");
  bytes[8 + 8 + 4 + 1] = 0;  // "f\0-x": a NUL inside the string
  EXPECT_LT(back.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
}

// Through the process edge: the crafted message is counted as a decode error and never
// reaches the handler; the next good one does.
TEST(LcmDecodeBounds, SubscriberNeverSeesACraftedMessage) {
  auto lcm = fl::MakeLcm("memq://");
  int handled = 0;
  lcm->Subscribe<bot_core::planar_lidar_t>(
      "LASER", [&](const bot_core::planar_lidar_t& m, const std::string&) {
        ++handled;
        EXPECT_EQ(m.nranges, 4);
      });
  const Wire bad = Lidar(2147483647);
  lcm->PublishRaw("LASER", bad.b.data(), bad.size(), 1);
  const Wire good = Lidar(4);
  lcm->PublishRaw("LASER", good.b.data(), good.size(), 2);
  g_largest = 0;
  while (lcm->HandleSubscriptions(0) > 0) {
  }
  EXPECT_EQ(handled, 1);
  EXPECT_EQ(lcm->decode_errors(), 1);
  EXPECT_LT(g_largest.load(), size_t{1} << 20);
}

}  // namespace

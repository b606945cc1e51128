#include "fusionloc/bench_faults/message_faults.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>

#include "bot_core/images_t.hpp"
#include "bot_core/planar_lidar_t.hpp"
#include "bot_core/pose_t.hpp"
#include "bot_core/rigid_transform_t.hpp"
#include "fusionloc/point_cloud_t.hpp"
#include "fusionloc/relative_pose_factor_t.hpp"
#include "fusionloc/stereo_calibration_t.hpp"
#include "fusionloc/wheel_odometry_t.hpp"

namespace fl::bench_faults {
namespace {

// One corruptible field of Msg: `count` elements (1 for a scalar), `set(msg, i, real, integer)`
// writes the bad value to element i (the real one for real fields, the integer one, clamped to
// the field's type, else) and returns the value written as text.
template <class T>
T ClampTo(int64_t v) {
  return static_cast<T>(
      std::clamp<int64_t>(v, std::numeric_limits<T>::min(), std::numeric_limits<T>::max()));
}

std::string FormatReal(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

template <class Msg>
struct Field {
  std::string name;  // "ranges[]" for an array
  bool integer;
  std::function<size_t(const Msg&)> count;
  std::function<std::string(Msg&, size_t, double, int64_t)> set;
};

template <class Msg>
struct Table {
  std::vector<Field<Msg>> fields;
  std::function<int64_t(const Msg&)> utime;
  std::function<void(Msg&, int64_t)> shift;
};

template <class Msg, class T>
Field<Msg> Scalar(const std::string& name, T Msg::*member) {
  constexpr bool kInteger = std::is_integral_v<T>;
  return {name, kInteger, [](const Msg&) { return size_t{1}; },
          [member](Msg& m, size_t, double real, int64_t integer) {
            if constexpr (kInteger) {
              m.*member = ClampTo<T>(integer);
              return std::to_string(m.*member);
            } else {
              m.*member = static_cast<T>(real);
              return FormatReal(real);
            }
          }};
}

template <class Msg, class T, size_t N>
Field<Msg> FixedArray(const std::string& name, T (Msg::*member)[N]) {
  return {name + "[]", false, [](const Msg&) { return N; },
          [member](Msg& m, size_t i, double real, int64_t) {
            (m.*member)[i] = static_cast<T>(real);
            return FormatReal(real);
          }};
}

template <class Msg, class T>
Field<Msg> Vector(const std::string& name, std::vector<T> Msg::*member) {
  return {name + "[]", false, [member](const Msg& m) { return (m.*member).size(); },
          [member](Msg& m, size_t i, double real, int64_t) {
            (m.*member)[i] = static_cast<T>(real);
            return FormatReal(real);
          }};
}

const Table<bot_core::planar_lidar_t>& LidarTable() {
  using M = bot_core::planar_lidar_t;
  static const Table<M> t{{Scalar("utime", &M::utime), Vector("ranges", &M::ranges),
                           Vector("intensities", &M::intensities), Scalar("rad0", &M::rad0),
                           Scalar("radstep", &M::radstep)},
                          [](const M& m) { return m.utime; },
                          [](M& m, int64_t d) { m.utime += d; }};
  return t;
}

const Table<bot_core::pose_t>& PoseTable() {
  using M = bot_core::pose_t;
  static const Table<M> t{
      {Scalar("utime", &M::utime), FixedArray("pos", &M::pos), FixedArray("vel", &M::vel),
       FixedArray("orientation", &M::orientation), FixedArray("rotation_rate", &M::rotation_rate),
       FixedArray("accel", &M::accel)},
      [](const M& m) { return m.utime; },
      [](M& m, int64_t d) { m.utime += d; }};
  return t;
}

const Table<bot_core::rigid_transform_t>& TransformTable() {
  using M = bot_core::rigid_transform_t;
  static const Table<M> t{
      {Scalar("utime", &M::utime), FixedArray("trans", &M::trans), FixedArray("quat", &M::quat)},
      [](const M& m) { return m.utime; },
      [](M& m, int64_t d) { m.utime += d; }};
  return t;
}

// The image fields that are not array lengths (size is data's length): corrupting width,
// height or row_stride makes the header disagree with the bytes, which a consumer must catch.
const Table<bot_core::images_t>& ImagesTable() {
  using M = bot_core::images_t;
  auto image_int = [](const std::string& name, int32_t bot_core::image_t::*member) {
    return Field<M>{"images[]." + name, true, [](const M& m) { return m.images.size(); },
                    [member](M& m, size_t i, double, int64_t v) {
                      m.images[i].*member = ClampTo<int32_t>(v);
                      return std::to_string(m.images[i].*member);
                    }};
  };
  static const Table<M> t{{Scalar("utime", &M::utime),
                           {"images[].utime", true, [](const M& m) { return m.images.size(); },
                            [](M& m, size_t i, double, int64_t v) {
                              m.images[i].utime = v;
                              return std::to_string(v);
                            }},
                           image_int("width", &bot_core::image_t::width),
                           image_int("height", &bot_core::image_t::height),
                           image_int("row_stride", &bot_core::image_t::row_stride),
                           image_int("pixelformat", &bot_core::image_t::pixelformat)},
                          [](const M& m) { return m.utime; },
                          [](M& m, int64_t d) {
                            m.utime += d;
                            for (auto& image : m.images) image.utime += d;
                          }};
  return t;
}

const Table<fusionloc::wheel_odometry_t>& OdometryTable() {
  using M = fusionloc::wheel_odometry_t;
  static const Table<M> t{
      {Scalar("utime", &M::utime), Scalar("x", &M::x), Scalar("y", &M::y),
       Scalar("theta", &M::theta), Scalar("v", &M::v), Scalar("omega", &M::omega),
       Scalar("left_ticks", &M::left_ticks), Scalar("right_ticks", &M::right_ticks)},
      [](const M& m) { return m.utime; },
      [](M& m, int64_t d) { m.utime += d; }};
  return t;
}

const Table<fusionloc::stereo_calibration_t>& CalibrationTable() {
  using M = fusionloc::stereo_calibration_t;
  static const Table<M> t{
      {Scalar("utime", &M::utime), Scalar("width", &M::width), Scalar("height", &M::height),
       Scalar("fx", &M::fx), Scalar("fy", &M::fy), Scalar("cx", &M::cx), Scalar("cy", &M::cy),
       Scalar("baseline", &M::baseline)},
      [](const M& m) { return m.utime; },
      [](M& m, int64_t d) { m.utime += d; }};
  return t;
}

const Table<fusionloc::relative_pose_factor_t>& FactorTable() {
  using M = fusionloc::relative_pose_factor_t;
  static const Table<M> t{
      {Scalar("utime_i", &M::utime_i), Scalar("utime_j", &M::utime_j),
       FixedArray("trans", &M::trans), FixedArray("quat", &M::quat),
       FixedArray("information", &M::information), Scalar("keyframe_id_i", &M::keyframe_id_i),
       Scalar("keyframe_id_j", &M::keyframe_id_j)},
      [](const M& m) { return m.utime_j; },
      [](M& m, int64_t d) {
        m.utime_i += d;
        m.utime_j += d;
      }};
  return t;
}

const Table<fusionloc::point_cloud_t>& CloudTable() {
  using M = fusionloc::point_cloud_t;
  static const Table<M> t{{Scalar("utime", &M::utime),
                           {"points[][]", false, [](const M& m) { return 3 * m.points.size(); },
                            [](M& m, size_t i, double v, int64_t) {
                              m.points[i / 3][i % 3] = static_cast<float>(v);
                              return FormatReal(v);
                            }},
                           Vector("intensities", &M::intensities)},
                          [](const M& m) { return m.utime; },
                          [](M& m, int64_t d) { m.utime += d; }};
  return t;
}

int64_t HashOf(const std::vector<uint8_t>& bytes) {
  if (bytes.size() < 8) return 0;
  uint64_t h = 0;
  for (int i = 0; i < 8; ++i) h = (h << 8) | bytes[static_cast<size_t>(i)];
  return static_cast<int64_t>(h);
}

// Calls fn(table, msg) with the decoded message of a known type; if fn returns true the
// message is encoded back into bytes. Returns what fn returned (false for unknown types).
template <class Fn>
bool WithMessage(std::vector<uint8_t>* bytes, Fn&& fn) {
  const int64_t h = HashOf(*bytes);
  auto run = [&](auto msg, const auto& table) {
    const int n = static_cast<int>(bytes->size());
    if (msg.decode(bytes->data(), 0, n) != n) return false;
    if (!fn(table, msg)) return false;
    bytes->resize(static_cast<size_t>(msg.getEncodedSize()));
    return msg.encode(bytes->data(), 0, static_cast<int>(bytes->size())) ==
           static_cast<int>(bytes->size());
  };
  if (h == bot_core::planar_lidar_t::getHash())
    return run(bot_core::planar_lidar_t(), LidarTable());
  if (h == bot_core::pose_t::getHash()) return run(bot_core::pose_t(), PoseTable());
  if (h == bot_core::rigid_transform_t::getHash())
    return run(bot_core::rigid_transform_t(), TransformTable());
  if (h == bot_core::images_t::getHash()) return run(bot_core::images_t(), ImagesTable());
  if (h == fusionloc::wheel_odometry_t::getHash())
    return run(fusionloc::wheel_odometry_t(), OdometryTable());
  if (h == fusionloc::stereo_calibration_t::getHash())
    return run(fusionloc::stereo_calibration_t(), CalibrationTable());
  if (h == fusionloc::relative_pose_factor_t::getHash())
    return run(fusionloc::relative_pose_factor_t(), FactorTable());
  if (h == fusionloc::point_cloud_t::getHash())
    return run(fusionloc::point_cloud_t(), CloudTable());
  return false;
}

template <class Msg>
std::vector<std::string> Names(const Table<Msg>& t) {
  std::vector<std::string> names;
  for (const auto& f : t.fields) names.push_back(f.name);
  return names;
}

}  // namespace

std::string MessageType(const std::vector<uint8_t>& bytes) {
  const int64_t h = HashOf(bytes);
  if (h == bot_core::planar_lidar_t::getHash()) return "bot_core.planar_lidar_t";
  if (h == bot_core::pose_t::getHash()) return "bot_core.pose_t";
  if (h == bot_core::rigid_transform_t::getHash()) return "bot_core.rigid_transform_t";
  if (h == bot_core::images_t::getHash()) return "bot_core.images_t";
  if (h == fusionloc::wheel_odometry_t::getHash()) return "fusionloc.wheel_odometry_t";
  if (h == fusionloc::stereo_calibration_t::getHash()) return "fusionloc.stereo_calibration_t";
  if (h == fusionloc::relative_pose_factor_t::getHash()) return "fusionloc.relative_pose_factor_t";
  if (h == fusionloc::point_cloud_t::getHash()) return "fusionloc.point_cloud_t";
  return "";
}

std::vector<std::string> CorruptibleFields(const std::string& type) {
  if (type == "bot_core.planar_lidar_t") return Names(LidarTable());
  if (type == "bot_core.pose_t") return Names(PoseTable());
  if (type == "bot_core.rigid_transform_t") return Names(TransformTable());
  if (type == "bot_core.images_t") return Names(ImagesTable());
  if (type == "fusionloc.wheel_odometry_t") return Names(OdometryTable());
  if (type == "fusionloc.stereo_calibration_t") return Names(CalibrationTable());
  if (type == "fusionloc.relative_pose_factor_t") return Names(FactorTable());
  if (type == "fusionloc.point_cloud_t") return Names(CloudTable());
  return {};
}

bool MessageUtime(const std::vector<uint8_t>& bytes, int64_t* utime) {
  std::vector<uint8_t> copy = bytes;
  bool decoded = false;
  WithMessage(&copy, [&](const auto& table, auto& msg) {
    *utime = table.utime(msg);
    decoded = true;
    return false;  // nothing to encode back
  });
  return decoded;
}

bool ShiftMessageTime(std::vector<uint8_t>* bytes, int64_t offset_us) {
  return WithMessage(bytes, [&](const auto& table, auto& msg) {
    table.shift(msg, offset_us);
    return true;
  });
}

bool CorruptMessageField(std::vector<uint8_t>* bytes, std::mt19937_64* rng, std::string* what) {
  const std::string type = MessageType(*bytes);
  return WithMessage(bytes, [&](const auto& table, auto& msg) {
    // Pick among the fields that have elements in this message.
    std::vector<size_t> usable;
    for (size_t i = 0; i < table.fields.size(); ++i) {
      if (table.fields[i].count(msg) > 0) usable.push_back(i);
    }
    if (usable.empty()) return false;
    const auto& field = table.fields[usable[(*rng)() % usable.size()]];
    const size_t n = field.count(msg);
    const size_t element = (*rng)() % n;
    static const double kReals[] = {std::numeric_limits<double>::quiet_NaN(),
                                    std::numeric_limits<double>::infinity(),
                                    -std::numeric_limits<double>::infinity(), 1e30};
    // Integers: int64 stamps get -1, -1e18, 1e18 (year 33658), INT64_MAX; int32 sizes the
    // same clamped: -1, INT32_MIN, INT32_MAX.
    static const int64_t kIntegers[] = {-1, -1000000000000000000LL, 1000000000000000000LL,
                                        std::numeric_limits<int64_t>::max()};
    const int kind = static_cast<int>((*rng)() % 4);
    const std::string value = field.set(msg, element, kReals[kind], kIntegers[kind]);
    if (what) {
      std::string name = field.name;
      const size_t bracket = name.find("[]");
      if (bracket != std::string::npos && n > 1) {
        name.replace(bracket, 2, "[" + std::to_string(element) + "]");
      }
      *what = type + "." + name + " = " + value;
    }
    return true;
  });
}

}  // namespace fl::bench_faults

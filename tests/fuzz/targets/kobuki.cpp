// Kobuki (wheel base) protocol decoder (fl-base-driver): a byte stream from the base is split
// into packets, their sub-payloads decoded and the Basic Sensor Data integrated into
// odometry; noise is counted and skipped, the pose stays finite.
#include <cmath>
#include <vector>

#include "../fuzz_entry.hpp"
#include "fusionloc/base/kobuki_protocol.hpp"
#include "fusionloc/base/odometry.hpp"

namespace kobuki = fl::base::kobuki;

int Fuzz_kobuki(const uint8_t* data, size_t size) {
  fl::fuzz::Input in(data, size);
  kobuki::PacketParser parser;
  fl::BaseGeometry geometry;
  geometry.wheel_radius_m = 0.035;
  geometry.track_m = 0.23;
  geometry.ticks_per_revolution = 2578.33;
  fl::base::WheelOdometry odometry(geometry, {});
  fl::Utime utime = 1000000;
  size_t fed = 0;
  while (!in.empty()) {
    const std::string_view chunk = in.Bytes(1 + in.Byte() % 96);
    fed += chunk.size();
    std::vector<std::vector<uint8_t>> payloads;
    parser.Feed(reinterpret_cast<const uint8_t*>(chunk.data()), chunk.size(), &payloads);
    for (const auto& payload : payloads) {
      const auto subs = kobuki::SplitPayload(payload);
      FL_FUZZ_CHECK(subs.has_value());  // the parser only hands on well-formed payloads
      for (const auto& sub : *subs) {
        if (sub.id == kobuki::kBasicSensorDataId) {
          const auto d = kobuki::DecodeBasicSensorData(sub.data);
          if (!d) continue;
          utime += 20000;
          fl::base::OdometrySample s;
          if (odometry.Update(utime, *d, &s)) {
            FL_FUZZ_CHECK(std::isfinite(s.x) && std::isfinite(s.y) && std::isfinite(s.theta));
          }
        }
      }
    }
    FL_FUZZ_CHECK(parser.buffered() <= fed);
  }
  return 0;
}

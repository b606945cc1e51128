// Faults made inside encoded LCM messages, for the fault benchmark (issue 27): read and shift
// a message's time stamp, and set one numeric field to a value no sensor sends (NaN, +-inf,
// a value out of any plausible range). The type is recognised by its LCM fingerprint (the
// first 8 bytes of the encoding), so that any channel carrying a known input type can be
// corrupted; array length fields are never touched (an encoding would no longer match its
// arrays: that is the decoder's fault class, covered by the fuzz targets).
//
// Known types: bot_core.planar_lidar_t, pose_t, rigid_transform_t, images_t;
// fusionloc.wheel_odometry_t, stereo_calibration_t, relative_pose_factor_t, point_cloud_t.
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace fl::bench_faults {

// The LCM type name of an encoded message ("bot_core.planar_lidar_t"), or "" if not known.
std::string MessageType(const std::vector<uint8_t>& bytes);

// The message's time stamp [us] (utime; utime_j of a factor); false if the type is unknown or
// the bytes do not decode.
bool MessageUtime(const std::vector<uint8_t>& bytes, int64_t* utime);

// Adds offset_us to every time stamp of the message (utime; utime_i and utime_j of a factor;
// the images' own stamps). False (bytes unchanged) if the type is unknown or does not decode.
bool ShiftMessageTime(std::vector<uint8_t>* bytes, int64_t offset_us);

// Sets one numeric field (chosen at random; one element of an array field) to a bad value:
// for real fields NaN, +inf, -inf or 1e30 (finite, out of any range); for integer fields (time
// stamps, image sizes) a negative or an enormous value. On success `what` names it, e.g.
// "bot_core.planar_lidar_t.ranges[17] = nan". False (bytes unchanged) if the type is unknown,
// the bytes do not decode, or the message has no numeric field to corrupt (an empty scan).
bool CorruptMessageField(std::vector<uint8_t>* bytes, std::mt19937_64* rng, std::string* what);

// The corruptible fields of a known type, as CorruptMessageField names them (arrays as
// "ranges[]"); empty for an unknown type. For documentation and tests.
std::vector<std::string> CorruptibleFields(const std::string& type);

}  // namespace fl::bench_faults

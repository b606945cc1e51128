// KITTI stereo folders into LCM logs.
//
// Two layouts are recognised:
//   raw drive (…_sync):  image_00/data/*.png (left), image_01/data/*.png (right), each with
//                        timestamps.txt ("2011-09-26 13:02:25.967790592", UTC);
//                        calib_cam_to_cam.txt (S_rect_00/01, P_rect_00/01);
//                        ground truth from poses_cam0_from_oxts.txt or --poses FILE.
//   odometry sequence:   image_0/*.png + image_1/*.png (gray) or image_2 + image_3 (colour,
//                        converted to gray); calib.txt (P0..P3); times.txt (seconds from the
//                        start; utime = kKittiOdometryEpochUtime + seconds);
//                        ground truth from --poses FILE (poses/NN.txt).
// Pose files: one line per frame, 12 numbers = row-major 3x4 T_cam0start_cam0(frame).
// A raw drive without a pose file but with oxts/ gets its ground truth from OXTS (see
// PosesFromOxts).
//
// Output channels:
//   CAMERA_TO_BASE      bot_core.rigid_transform_t T_base_camera (base = cam0 with base axes;
//                       the left camera's offset from the drive's calibration), with ...
//   STEREO_CALIBRATION  fusionloc.stereo_calibration_t, before the first frame and again every
//                       calibration_period_s (so a late subscriber gets it).
//   STEREO              bot_core.images_t: LEFT (0) then RIGHT (1), 8-bit GRAY, row_stride =
//                       width, utime = the left image's time stamp.
//   LASER_3D_TO_BASE    bot_core.rigid_transform_t T_base_velodyne (T_base_cam0 * Tr), with
//                       CAMERA_TO_BASE, when the folder has Velodyne scans (and laser_3d).
//   LASER_3D            fusionloc.laser_scan_3d_t per frame, just before its STEREO, frame
//                       "velodyne", the scan's finite points in the Velodyne frame, utime =
//                       the frame's (KITTI triggers the cameras when the scanner faces
//                       forward).
//   GROUND_TRUTH        bot_core.pose_t per frame: T_world_base with world = the base frame
//                       at the first converted frame, T_world_base = R_bc * T_c0_ci * R_bc^-1
//                       (R_bc: optical camera frame -> base frame; see kRotationBaseCamera).
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"
#include "fusionloc/common/time.hpp"
#include "fusionloc/importers/convert_summary.hpp"

namespace fl::importers {

// Epoch added to KITTI-odometry times.txt (seconds from the sequence start):
// 2011-01-01T00:00:00Z, so the utimes look like (and never collide with) real dates.
constexpr Utime kKittiOdometryEpochUtime = 1293840000LL * 1000000LL;

struct KittiOptions {
  int start_frame = 0;  // [frames] first frame to convert (0 = the first)
  int max_frames = -1;  // [frames] at most this many frames (-1 = all)
  // Ground-truth pose file (12 numbers a line). "" = <folder>/poses_cam0_from_oxts.txt if it
  // exists, else (raw drives) computed from <folder>/oxts/, else none.
  std::string poses_file;
  // With no pose file: false = error (with the fix), true = convert without GROUND_TRUTH.
  bool allow_no_ground_truth = false;
  // Odometry sequences with both gray and colour images: "auto" (gray if present), "gray"
  // (image_0/1) or "color" (image_2/3).
  std::string cameras = "auto";
  double calibration_period_s = 1.0;  // [s] republish STEREO_CALIBRATION (0 = only once)
  // Velodyne scans (velodyne/ or velodyne_points/data/) as LASER_3D when the folder has them.
  bool laser_3d = true;

  template <class A>
  void Serialize(A* a) {
    a->Visit("start_frame", &start_frame);
    a->Visit("max_frames", &max_frames);
    a->Visit("poses_file", &poses_file);
    a->Visit("allow_no_ground_truth", &allow_no_ground_truth);
    a->Visit("cameras", &cameras);
    a->Visit("calibration_period_s", &calibration_period_s);
    a->Visit("laser_3d", &laser_3d);
  }
  Status Validate() const;
};

// Rotation taking optical-camera coordinates (x right, y down, z forward) to base coordinates
// (x forward, y left, z up): p_base = R_bc * p_cam.
Eigen::Matrix3d RotationBaseCamera();

// A rectified stereo pair's calibration as read from a KITTI folder.
struct KittiCalibration {
  int width = 0, height = 0;                                      // [px]
  double fx = 0, fy = 0, cx = 0, cy = 0;                          // [px]
  double baseline = 0;                                            // [m]
  Eigen::Vector3d left_center_in_cam0 = Eigen::Vector3d::Zero();  // [m] left optical centre
};

// One folder, scanned and checked, before any image is read.
struct KittiSequence {
  std::string folder;
  bool raw_layout = false;               // true: raw drive, false: odometry sequence
  std::vector<std::string> left_images;  // paths, in frame order
  std::vector<std::string> right_images;
  std::vector<Utime> utimes;  // [us] per frame (left camera)
  KittiCalibration calibration;
  std::string poses_path;                           // pose file or oxts folder used; "" if none
  std::vector<Eigen::Isometry3d> T_cam0start_cam0;  // per frame, empty if no poses
  std::vector<std::string> warnings;  // e.g. a times.txt longer than the images (first N used)
  // Velodyne scans, when the folder has them (odometry: velodyne/*.bin; raw drive:
  // velodyne_points/data/*.bin): one path per frame, same order as the images; empty if none.
  std::vector<std::string> velodyne_scans;
  // Velodyne -> rectified camera 0 (odometry: calib.txt `Tr`; raw drive:
  // calib_velo_to_cam.txt R, T then R_rect_00). Meaningful only with velodyne_scans.
  Eigen::Isometry3d T_cam0_velo = Eigen::Isometry3d::Identity();
};

// One Velodyne scan of a KITTI .bin file (N x 4 float32: x, y, z [m] in the Velodyne frame,
// reflectance in [0, 1]).
struct VelodyneScan {
  std::vector<Eigen::Vector3f> points;  // [m] Velodyne frame, finite points only
  std::vector<float> intensities;       // [-] reflectance, one per point
  int dropped_non_finite = 0;           // points with a NaN/inf coordinate or intensity, dropped
};

// Reads a KITTI Velodyne .bin file. Throws std::runtime_error naming the file if it cannot be
// read or its size is not a multiple of 16 bytes (4 float32 per point).
VelodyneScan ReadVelodyneBin(const std::string& path);

// `Tr` (3x4 row-major, Velodyne -> camera 0) from the text of an odometry calib.txt (`name`
// stands for the file in errors). Throws std::runtime_error naming the file if `Tr` is missing
// (with the fix), malformed, or its 3x3 part is not a rotation.
Eigen::Isometry3d ParseKittiVelodyneToCamera(const std::string& text, const std::string& name);

// Scans and validates a folder (layout, image lists, time stamps, calibration, poses).
// Throws std::runtime_error naming the file (and line) and the fix on any inconsistency.
KittiSequence ScanKittiFolder(const KittiOptions& options, const std::string& folder);

// Ground truth of a raw drive from its OXTS records, the way the KITTI devkit does it
// (convertOxtsToPose: Mercator projection scaled by the first frame's latitude, orientation
// Rz(yaw) Ry(pitch) Rx(roll), relative to the first frame), expressed as left-camera poses:
// T_cam0(0)_cam0(i) = T_cam0_imu * T_imu(0)_imu(i) * T_cam0_imu^-1 with cam0 the rectified
// left camera: T_cam0_imu = R_rect_00 (calib_cam_to_cam.txt) * T_velo_to_cam
// (calib_velo_to_cam.txt) * T_imu_to_velo (calib_imu_to_velo.txt). One pose per
// oxts/data/*.txt file. On the shared drive this reproduces poses_cam0_from_oxts.txt to 1e-6 m.
std::vector<Eigen::Isometry3d> PosesFromOxts(const std::string& folder);

// Parses "YYYY-MM-DD HH:MM:SS.fffffffff" (UTC) to microseconds since the epoch (rounded).
// Returns false if the text is not in that form.
bool ParseKittiTimestamp(const std::string& text, Utime* utime);

// The text parsers ScanKittiFolder uses on a folder's files (`name` stands for the file in
// errors; each throws std::runtime_error "NAME:LINE: what is wrong"):
//   calibration: raw_layout, calib_cam_to_cam.txt (S_rect_00/01 give width and height,
//     P_rect_00/01 the pair); else calib.txt (P0/P1, or P2/P3 with color; width and height
//     stay 0: the images give them).
//   times: times.txt, seconds from the start (utime = kKittiOdometryEpochUtime + seconds).
//   timestamps: a raw drive's timestamps.txt (ParseKittiTimestamp lines).
//   poses: 12 numbers a line (row-major 3x4), the 3x3 part a rotation to 1e-3.
// A time or pose list longer than the images present is cut to the first N with a warning
// (images trimmed, the lists not); a shorter one is an error.
KittiCalibration ParseKittiCalibration(const std::string& text, const std::string& name,
                                       bool raw_layout, bool color);
std::vector<Utime> ParseKittiTimes(const std::string& text, const std::string& name);
std::vector<Utime> ParseKittiTimestamps(const std::string& text, const std::string& name);
std::vector<Eigen::Isometry3d> ParseKittiPoses(const std::string& text, const std::string& name);

// Converts a folder to the LCM log `out_log` (written to out_log.partial and renamed when
// complete; on any error nothing is left at out_log and the exception is rethrown).
ConvertSummary ConvertKitti(const KittiOptions& options, const std::string& folder,
                            const std::string& out_log);

}  // namespace fl::importers

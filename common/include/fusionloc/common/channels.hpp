// LCM channel names shared by every process. One place, so drivers, estimators, fusion and
// tools agree; each process also lets the user rename its channels from the command line.
#pragma once

namespace fl::channels {

// ---- sensors (drivers, simulator, importers) ----
constexpr const char* kLaser = "LASER";                           // bot_core.planar_lidar_t
constexpr const char* kOdometry = "ODOMETRY";                     // fusionloc.wheel_odometry_t
constexpr const char* kBaseCommand = "BASE_COMMAND";              // fusionloc.base_command_t
constexpr const char* kStereo = "STEREO";                         // bot_core.images_t (LEFT, RIGHT)
constexpr const char* kStereoCalibration = "STEREO_CALIBRATION";  // fusionloc.stereo_calibration_t
// The robot description (config/robot/<robot>.yaml, docs/ROBOT.md): sensor mountings as
// bot_core.rigid_transform_t T_base_sensor (p_base = R p_sensor + t), published by whatever
// describes the robot (fl-sim, the importers, fl-robot-description) first and every 1 s.
// libbot2's naming: <FROM>_TO_<TO>.
constexpr const char* kLaserToBase = "LASER_TO_BASE";    // T_base_laser
constexpr const char* kCameraToBase = "CAMERA_TO_BASE";  // T_base_camera (left, optical frame)
// Reference pose of the base in the world frame (simulator truth, KITTI OXTS poses, CARMEN
// corrected poses): bot_core.pose_t. Never read by an estimator.
constexpr const char* kGroundTruth = "GROUND_TRUTH";

// ---- laser RBPF-SLAM ----
constexpr const char* kRbpfPose = "RBPF_POSE";              // bot_core.pose_t, at scan rate
constexpr const char* kRbpfFactors = "RBPF_FACTORS";        // fusionloc.relative_pose_factor_t
constexpr const char* kRbpfMap = "RBPF_MAP";                // fusionloc.occupancy_grid_t
constexpr const char* kRbpfTrajectory = "RBPF_TRAJECTORY";  // fusionloc.trajectory_t

// ---- stereo visual odometry ----
constexpr const char* kVoPose = "VO_POSE";        // bot_core.pose_t
constexpr const char* kVoFactors = "VO_FACTORS";  // fusionloc.relative_pose_factor_t
constexpr const char* kVoPoints = "VO_POINTS";  // fusionloc.point_cloud_t (keyframe, camera frame)

// ---- fusion ----
constexpr const char* kFusedPose = "FUSED_POSE";              // fusionloc.fused_pose_t
constexpr const char* kFusedTrajectory = "FUSED_TRAJECTORY";  // fusionloc.trajectory_t
constexpr const char* kFusedMap = "FUSED_MAP";                // fusionloc.point_cloud_t (map frame)

// ---- health: STATUS_<PROCESS>, e.g. STATUS_FL_SIM; subscribe "STATUS_.*" for all ----
constexpr const char* kStatusPrefix = "STATUS_";

}  // namespace fl::channels

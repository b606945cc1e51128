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
constexpr const char* kLaser3d = "LASER_3D";  // fusionloc.laser_scan_3d_t (multi-line scanner)
// The robot description (config/robot/<robot>.yaml, docs/ROBOT.md): sensor mountings as
// bot_core.rigid_transform_t T_base_sensor (p_base = R p_sensor + t), published by whatever
// describes the robot (fl-sim, the importers, fl-robot-description) first and every 1 s.
// libbot2's naming: <FROM>_TO_<TO>.
constexpr const char* kLaserToBase = "LASER_TO_BASE";    // T_base_laser
constexpr const char* kCameraToBase = "CAMERA_TO_BASE";  // T_base_camera (left, optical frame)
constexpr const char* kLaser3dToBase = "LASER_3D_TO_BASE";  // T_base_laser3d (LASER_3D's frame)
// Reference pose of the base in the world frame (simulator truth, KITTI OXTS poses, CARMEN
// corrected poses): bot_core.pose_t. Never read by an estimator.
constexpr const char* kGroundTruth = "GROUND_TRUTH";

// ---- laser RBPF-SLAM ----
constexpr const char* kRbpfPose = "RBPF_POSE";              // bot_core.pose_t, at scan rate
constexpr const char* kRbpfFactors = "RBPF_FACTORS";        // fusionloc.relative_pose_factor_t
constexpr const char* kRbpfMap = "RBPF_MAP";                // fusionloc.occupancy_grid_t
constexpr const char* kRbpfTrajectory = "RBPF_TRAJECTORY";  // fusionloc.trajectory_t
// fl-rbpf-slam --localize: the robot's pose in the saved map (T_map_base), from an operator
// or a planner, e.g. RViz's "2D Pose Estimate" bridged to LCM.
constexpr const char* kInitialPose = "INITIAL_POSE";        // bot_core.pose_t

// ---- stereo visual odometry ----
constexpr const char* kVoPose = "VO_POSE";        // bot_core.pose_t
constexpr const char* kVoFactors = "VO_FACTORS";  // fusionloc.relative_pose_factor_t
constexpr const char* kVoPoints = "VO_POINTS";  // fusionloc.point_cloud_t (keyframe, camera frame)

// ---- fusion ----
constexpr const char* kFusedPose = "FUSED_POSE";              // fusionloc.fused_pose_t
constexpr const char* kFusedTrajectory = "FUSED_TRAJECTORY";  // fusionloc.trajectory_t
constexpr const char* kFusedMap = "FUSED_MAP";                // fusionloc.point_cloud_t (map frame)

// ---- process management (libbot2's procman protocol; docs/PROCMAN.md) ----
constexpr const char* kPmdOrders = "PMD_ORDERS2";     // bot_procman.orders2_t, sheriff -> deputy
constexpr const char* kPmdInfo = "PMD_INFO2";         // bot_procman.info2_t, deputy status, 1 Hz
constexpr const char* kPmdPrintf = "PMD_PRINTF";      // bot_procman.printf_t, command output
constexpr const char* kPmdDiscover = "PMD_DISCOVER";  // bot_procman.discovery_t
// fl-procman-ctl -> fl-procman-sheriff: one order line ("restart fusion"), as a printf_t
// (sheriff_id 0, deputy_name = the sender, text = the line).
constexpr const char* kPmdSheriffCtl = "PMD_SHERIFF_CTL";

// ---- health: STATUS_<PROCESS>, e.g. STATUS_FL_SIM; subscribe "STATUS_.*" for all ----
constexpr const char* kStatusPrefix = "STATUS_";

// ---- signed procman orders (beyond libbot2; docs/PROCMAN_SECURITY.md) ----
// fusionloc.procman_signed_orders_t: a bot_procman.orders2_t with a MAC, sheriff -> deputy
// (procman/include/fusionloc/procman/order_auth.hpp).
constexpr const char* kPmdOrdersSigned = "PMD_ORDERS2_SIGNED";
// fl-procman-ctl's text orders signed with the procman key (fusionloc.procman_signed_orders_t
// whose payload is the LCM-encoded bot_procman.printf_t order); a sheriff that signs its orders
// takes ctl orders only this way.
constexpr const char* kPmdSheriffCtlSigned = "PMD_SHERIFF_CTL_SIGNED";

}  // namespace fl::channels

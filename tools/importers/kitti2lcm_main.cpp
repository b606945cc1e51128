// fl-kitti2lcm: a KITTI raw drive or odometry sequence into an LCM log with STEREO,
// STEREO_CALIBRATION and GROUND_TRUTH. Thin adapter over fl::importers::ConvertKitti.
#include <exception>
#include <filesystem>
#include <iostream>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/importers/kitti.hpp"

int main(int argc, char** argv) {
  fl::Program program("fl-kitti2lcm",
                      "Converts a KITTI raw drive (image_00/ image_01/ calib_cam_to_cam.txt) or\n"
                      "odometry sequence (image_0/ image_1/ or image_2/ image_3/, calib.txt,\n"
                      "times.txt) into an LCM log: STEREO (images_t, gray), STEREO_CALIBRATION\n"
                      "and GROUND_TRUTH (pose_t of the base; world = base at the first frame).");
  fl::CommandLine& cli = program.cli();
  std::string folder, out, poses, cameras;
  int start = -1, max_frames = 0;
  bool no_gt = false, no_laser_3d = false;
  fl::importers::KittiOptions options;
  program.AddOptions(&options, "a KittiOptions file, see docs/IMPORTERS.md");
  cli.AddPositional("FOLDER", &folder, "KITTI folder", /*required=*/false);
  cli.AddPositional("OUT", &out, "LCM log to write (default: FOLDER's name with .lcmlog, here)",
                    /*required=*/false);
  cli.AddFlag("poses", &poses,
              "ground-truth pose file, 12 numbers a line (default: FOLDER/"
              "poses_cam0_from_oxts.txt)");
  cli.AddFlag("no-ground-truth", &no_gt, "convert without GROUND_TRUTH if no pose file exists");
  cli.AddFlag("start", &start, "first frame (overrides the config; -1 = config)");
  cli.AddFlag("max-frames", &max_frames, "at most this many frames (overrides; 0 = config)");
  cli.AddFlag("cameras", &cameras, "odometry sequences: auto, gray (image_0/1) or color (2/3)");
  cli.AddFlag("no-laser-3d", &no_laser_3d,
              "do not write the Velodyne scans (LASER_3D, about 2 MB a frame) even if present");
  cli.AddEpilog(
      "\nExample:\n"
      "  fl-kitti2lcm ../shared/data/stereo/kitti_raw_2011_09_26_drive_0001 kitti0001.lcmlog\n"
      "Exit status: 0 done, 1 conversion failed (nothing written), 2 usage or\n"
      "configuration error.\n");
  cli.AddCheck([&]() -> std::string {  // the flags override the options file
    if (!poses.empty()) options.poses_file = poses;
    if (no_gt) options.allow_no_ground_truth = true;
    if (start >= 0) options.start_frame = start;
    if (max_frames != 0) options.max_frames = max_frames;
    if (!cameras.empty()) options.cameras = cameras;
    if (no_laser_3d) options.laser_3d = false;
    const fl::Status valid = options.Validate();
    return valid.ok() ? "" : "invalid options: " + valid.message();
  });
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    if (folder.empty()) throw fl::UsageError("missing FOLDER (the KITTI folder to convert)");
    if (out.empty()) {
      std::filesystem::path p(folder);
      if (p.filename().empty()) p = p.parent_path();
      out = p.filename().string() + ".lcmlog";
    }
    const auto summary = fl::importers::ConvertKitti(options, folder, out);
    std::cout << summary.ToString();
    return fl::kExitOk;
  });
}

// fl-stereo-calibrate: calibrates a stereo pair from chessboard image pairs and writes the
// calibration file fl-stereo-driver reads, with the RMS reprojection error and a rectified
// preview with epipolar lines.
#include <cstdio>
#include <opencv2/imgcodecs.hpp>

#include "fusionloc/common/log.hpp"
#include "fusionloc/common/program.hpp"
#include "fusionloc/stereo/chessboard_calibration.hpp"
#include "fusionloc/stereo/sources.hpp"

int main(int argc, char** argv) {
  fl::Program program("fl-stereo-calibrate",
                      "Stereo calibration from chessboard image pairs (a folder with left/ + "
                      "right/, or image_0/ + image_1/, same file names): intrinsics and "
                      "distortion of both cameras and their relative pose, written as the "
                      "calibration file of fl-stereo-driver.");
  fl::stereo::ChessboardOptions options;
  program.AddOptions(&options, "config/stereo_calibrate.yaml");
  std::string folder, out, preview;
  program.cli().AddPositional("FOLDER", &folder, "folder of chessboard image pairs");
  program.cli().AddFlag("out", &out, "calibration file to write (e.g. config/robot/rig.yaml)");
  program.cli().AddFlag("preview", &preview,
                        "rectified preview to write (PNG, the first pair with epipolar lines; "
                        "default: OUT with _preview.png)");
  program.cli().AddEpilog(
      "\nExample:\n"
      "  fl-stereo-calibrate pairs/ --out rig.yaml   # 9x6 inner corners, 25 mm squares\n"
      "Take 15-30 pairs: the whole board in both views, tilted, near and far, in the corners "
      "of the image. An RMS above 0.5 px usually means blur or a wrong square size.\n");
  if (!program.Parse(argc, argv)) return program.exit_code();
  return program.Run([&] {
    if (out.empty()) throw fl::UsageError("give --out FILE for the calibration");
    if (preview.empty()) {
      const size_t dot = out.rfind('.');
      preview = (dot == std::string::npos ? out : out.substr(0, dot)) + "_preview.png";
    }
    const fl::stereo::ImagePairs pairs = fl::stereo::ListImagePairs(folder, false);
    std::vector<cv::Mat> left, right;
    for (size_t i = 0; i < pairs.left.size(); ++i) {
      left.push_back(cv::imread(pairs.left[i], cv::IMREAD_GRAYSCALE));
      right.push_back(cv::imread(pairs.right[i], cv::IMREAD_GRAYSCALE));
      if (left.back().empty() || right.back().empty()) {
        throw std::runtime_error("cannot read " +
                                 (left.back().empty() ? pairs.left[i] : pairs.right[i]));
      }
    }
    const fl::stereo::StereoCalibrationResult r = fl::stereo::CalibrateStereo(left, right, options);
    for (int i : r.rejected) {
      FL_LOG(WARN) << "board not found in both views of " << pairs.left[static_cast<size_t>(i)];
    }
    fl::stereo::SaveRigCalibration(r.rig, out,
                                   "fl-stereo-calibrate " + folder + ": " +
                                       std::to_string(r.used.size()) + " pairs, RMS " +
                                       std::to_string(r.rms_px) + " px");
    const size_t first = static_cast<size_t>(r.used.front());
    if (!cv::imwrite(preview, fl::stereo::RectifiedPreview(r.rig, left[first], right[first]))) {
      throw std::runtime_error("cannot write the preview '" + preview + "'");
    }
    std::printf(
        "pairs used %zu of %zu; RMS reprojection error %.3f px (left alone %.3f, right %.3f)\n"
        "left fx %.2f fy %.2f cx %.2f cy %.2f; right fx %.2f fy %.2f; baseline %.4f m\n"
        "wrote %s and %s\n",
        r.used.size(), left.size(), r.rms_px, r.left_rms_px, r.right_rms_px, r.rig.left.fx,
        r.rig.left.fy, r.rig.left.cx, r.rig.left.cy, r.rig.right.fx, r.rig.right.fy,
        cv::norm(r.rig.T()), out.c_str(), preview.c_str());
    if (r.rms_px > 1.0) {
      FL_LOG(WARN) << "RMS " << r.rms_px << " px is high: blurred views, a board that is not "
                   << "flat, or a wrong square_m?";
    }
    return 0;
  });
}

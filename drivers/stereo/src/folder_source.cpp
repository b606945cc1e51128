#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <stdexcept>

#include "fusionloc/stereo/sources.hpp"

namespace fl::stereo {
namespace fs = std::filesystem;

namespace {

bool IsImage(const fs::path& p) {
  static const std::set<std::string> kExt{".png", ".jpg", ".jpeg", ".pgm",
                                          ".ppm", ".bmp", ".tif",  ".tiff"};
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return kExt.count(e) > 0;
}

std::map<std::string, std::string> ImagesByStem(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.is_regular_file() && IsImage(e.path())) {
      out[e.path().stem().string()] = e.path().string();
    }
  }
  return out;
}

}  // namespace

ImagePairs ListImagePairs(const std::string& folder, bool skip_unpaired) {
  if (!fs::is_directory(folder)) {
    throw std::runtime_error("image folder '" + folder + "' does not exist or is not a folder");
  }
  const fs::path f(folder);
  ImagePairs pairs;
  if (fs::is_directory(f / "image_00" / "data") && fs::is_directory(f / "image_01" / "data")) {
    pairs.layout = "KITTI raw";
    pairs.left_dir = (f / "image_00" / "data").string();
    pairs.right_dir = (f / "image_01" / "data").string();
  } else if (fs::is_directory(f / "image_0") && fs::is_directory(f / "image_1")) {
    pairs.layout = "KITTI odometry";
    pairs.left_dir = (f / "image_0").string();
    pairs.right_dir = (f / "image_1").string();
  } else if (fs::is_directory(f / "left") && fs::is_directory(f / "right")) {
    pairs.layout = "left/right";
    pairs.left_dir = (f / "left").string();
    pairs.right_dir = (f / "right").string();
  } else {
    throw std::runtime_error("folder '" + folder +
                             "' has no image pairs: expected image_00/data/ + image_01/data/ "
                             "(KITTI raw), image_0/ + image_1/ (KITTI odometry) or left/ + "
                             "right/, with the same file names on both sides");
  }
  const auto left = ImagesByStem(pairs.left_dir), right = ImagesByStem(pairs.right_dir);
  for (const auto& [stem, path] : left) {
    const auto r = right.find(stem);
    if (r == right.end()) {
      pairs.unpaired.push_back(path);
    } else {
      pairs.left.push_back(path);
      pairs.right.push_back(r->second);
    }
  }
  for (const auto& [stem, path] : right) {
    if (!left.count(stem)) pairs.unpaired.push_back(path);
  }
  if (pairs.left.empty()) {
    throw std::runtime_error("folder '" + folder + "' (" + pairs.layout + " layout): no image in " +
                             pairs.left_dir + " has a partner of the same name in " +
                             pairs.right_dir);
  }
  if (!pairs.unpaired.empty() && !skip_unpaired) {
    throw std::runtime_error(
        "folder '" + folder + "': " + std::to_string(pairs.unpaired.size()) +
        " image(s) without a partner of the same name on the other side, the first: " +
        pairs.unpaired.front() +
        " (add the missing image, or set folder.skip_unpaired: true to skip them)");
  }
  return pairs;
}

fl::Status FolderSourceOptions::Validate() const {
  if (!(rate_hz > 0) || !std::isfinite(rate_hz)) {
    return fl::Status::Error("folder.rate_hz must be > 0");
  }
  if (start_frame < 0) return fl::Status::Error("folder.start_frame must be >= 0");
  if (max_frames == 0 || max_frames < -1) {
    return fl::Status::Error("folder.max_frames must be -1 (all) or > 0");
  }
  return fl::Status::Ok();
}

FolderSource::FolderSource(const std::string& folder, const FolderSourceOptions& options,
                           Utime start_utime)
    : options_(options),
      pairs_(ListImagePairs(folder, options.skip_unpaired)),
      start_utime_(start_utime) {
  begin_ = std::min(static_cast<size_t>(options.start_frame), pairs_.left.size());
  end_ = pairs_.left.size();
  if (options.max_frames > 0)
    end_ = std::min(end_, begin_ + static_cast<size_t>(options.max_frames));
  if (begin_ >= end_) {
    throw std::runtime_error("folder '" + folder + "' has " + std::to_string(pairs_.left.size()) +
                             " pairs; start_frame " + std::to_string(options.start_frame) +
                             " leaves none");
  }
  next_ = begin_;
}

Utime FolderSource::FrameUtime(int64_t i) const {
  return start_utime_ +
         static_cast<Utime>(std::llround(static_cast<double>(i) * 1e6 / options_.rate_hz));
}

bool FolderSource::Next(StereoFrame* frame) {
  while (true) {
    if (next_ >= end_) {
      if (!options_.loop) return false;
      next_ = begin_;
    }
    const size_t i = next_++;
    const int64_t k = played_ + unreadable_;  // frame number in data time
    cv::Mat l = cv::imread(pairs_.left[i], cv::IMREAD_UNCHANGED);
    cv::Mat r = cv::imread(pairs_.right[i], cv::IMREAD_UNCHANGED);
    std::string problem;
    if (l.empty() || r.empty()) {
      problem = "cannot read " + (l.empty() ? pairs_.left[i] : pairs_.right[i]);
    } else if (l.size() != r.size() || l.type() != r.type()) {
      problem = pairs_.left[i] + " and its right image differ in size or type";
    } else if (l.depth() != CV_8U || !(l.channels() == 1 || l.channels() == 3)) {
      problem = pairs_.left[i] + ": not an 8-bit gray or color image";
    }
    if (!problem.empty()) {
      ++unreadable_;
      last_problem_ = problem;
      continue;
    }
    frame->utime = FrameUtime(k);
    frame->left = l;
    frame->right = r;
    frame->name = fs::path(pairs_.left[i]).filename().string();
    ++played_;
    return true;
  }
}

}  // namespace fl::stereo

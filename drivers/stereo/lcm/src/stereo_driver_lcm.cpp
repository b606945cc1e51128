#include "fusionloc/stereo/stereo_driver_lcm.hpp"

#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <thread>

#include "fusionloc/common/channels.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/common/shutdown.hpp"
#include "fusionloc/importers/kitti.hpp"
#include "fusionloc/status_t.hpp"

namespace fl::stereo {

fl::Status StereoDriverOptions::Validate() const {
  if (!(calibration_period_s >= 0)) return fl::Status::Error("calibration_period_s must be >= 0");
  if (!(capture_period_s >= 0)) return fl::Status::Error("capture_period_s must be >= 0");
  if (auto s = folder.Validate(); !s.ok()) return s;
  return camera.Validate();
}

RigCalibration CalibrationForFolder(const std::string& calibration_path,
                                    const std::string& folder) {
  if (!calibration_path.empty()) return LoadRigCalibration(calibration_path);
  const ImagePairs pairs = ListImagePairs(folder, true);
  if (pairs.layout == "left/right") {
    throw UsageError("folder '" + folder +
                     "' (left/ + right/) has no calibration of its own: give --calibration "
                     "FILE (made by fl-stereo-calibrate)");
  }
  fl::importers::KittiOptions ko;
  ko.allow_no_ground_truth = true;
  const fl::importers::KittiCalibration k = fl::importers::ScanKittiFolder(ko, folder).calibration;
  RigCalibration c;
  c.width = k.width;
  c.height = k.height;
  c.rectified = true;
  c.left = {k.fx, k.fy, k.cx, k.cy, {}};
  c.right = c.left;
  c.translation = {-k.baseline, 0, 0};
  return c;
}

fusionloc::stereo_calibration_t CalibrationToLcm(const RectifiedCamera& c, Utime utime) {
  fusionloc::stereo_calibration_t m{};
  m.utime = utime;
  m.width = c.width;
  m.height = c.height;
  m.fx = c.fx;
  m.fy = c.fy;
  m.cx = c.cx;
  m.cy = c.cy;
  m.baseline = c.baseline;
  m.rectified = true;  // what the driver publishes is rectified
  return m;
}

bot_core::images_t PairToLcm(const cv::Mat& left, const cv::Mat& right, Utime utime) {
  bot_core::images_t pair{};
  pair.utime = utime;
  pair.n_images = 2;
  const int16_t kLeft = bot_core::images_t::LEFT, kRight = bot_core::images_t::RIGHT;
  pair.image_types = {kLeft, kRight};
  for (const cv::Mat* m : {&left, &right}) {
    cv::Mat c = m->isContinuous() ? *m : m->clone();
    bot_core::image_t im{};
    im.utime = utime;
    im.width = c.cols;
    im.height = c.rows;
    im.row_stride = c.cols * c.channels();
    const int32_t gray = bot_core::image_t::PIXEL_FORMAT_GRAY;
    const int32_t bgr = bot_core::image_t::PIXEL_FORMAT_BGR;
    im.pixelformat = c.channels() == 1 ? gray : bgr;
    im.size = im.row_stride * c.rows;
    im.data.assign(c.data, c.data + im.size);
    im.nmetadata = 0;
    pair.images.push_back(std::move(im));
  }
  return pair;
}

std::vector<ChannelSpec> StereoDriverNode::Outputs() {
  return {{channels::kStereo, "bot_core.images_t", "rectified LEFT + RIGHT, GRAY (or BGR)"},
          {channels::kStereoCalibration, "fusionloc.stereo_calibration_t",
           "rectified intrinsics and baseline; first and every calibration_period_s"}};
}

StereoDriverNode::StereoDriverNode(const StereoDriverOptions& options, const std::string& folder,
                                   LcmInterface* lcm, const ChannelMap& channels)
    : options_(options),
      lcm_(lcm),
      ch_stereo_(channels(channels::kStereo)),
      ch_calibration_(channels(channels::kStereoCalibration)),
      status_(lcm, kProgram) {
  if (!folder.empty()) {
    const RigCalibration calib = CalibrationForFolder(options.calibration, folder);
    rectifier_ = std::make_unique<Rectifier>(calib);
    folder_ = std::make_unique<FolderSource>(folder, options.folder, lcm->Now());
    // The first pair must fit the calibration (a wrong file is a clear error, not a crash).
    const cv::Mat first = cv::imread(folder_->pairs().left.front(), cv::IMREAD_UNCHANGED);
    if (first.cols != calib.width || first.rows != calib.height) {
      throw std::runtime_error(folder_->pairs().left.front() + " is " + std::to_string(first.cols) +
                               "x" + std::to_string(first.rows) + " but the calibration is for " +
                               std::to_string(calib.width) + "x" + std::to_string(calib.height) +
                               " (wrong calibration file for this folder?)");
    }
    FL_LOG(INFO) << folder << ": " << folder_->size() << " pairs (" << folder_->pairs().layout
                 << "), " << options.folder.rate_hz << " Hz"
                 << (folder_->pairs().unpaired.empty()
                         ? std::string()
                         : ", " + std::to_string(folder_->pairs().unpaired.size()) +
                               " unpaired image(s) skipped");
  } else {
    if (options.calibration.empty() && options.capture_folder.empty()) {
      throw UsageError(
          "a camera needs its calibration: --calibration FILE (fl-stereo-calibrate; to take "
          "its chessboard pairs first: --capture DIR)");
    }
    if (!options.calibration.empty()) {
      const RigCalibration calib = LoadRigCalibration(options.calibration);
      if (calib.width * 2 != options.camera.width || calib.height != options.camera.height) {
        throw ConfigError("calibration " + options.calibration + " is for " +
                          std::to_string(calib.width) + "x" + std::to_string(calib.height) +
                          " views but camera.width x height is " +
                          std::to_string(options.camera.width) + "x" +
                          std::to_string(options.camera.height) + " (two views side by side)");
      }
      rectifier_ = std::make_unique<Rectifier>(calib);
    }
    if (!options.capture_folder.empty()) {
      std::filesystem::create_directories(options.capture_folder + "/left");
      std::filesystem::create_directories(options.capture_folder + "/right");
    }
    camera_ = std::make_unique<SideBySideCamera>(MakeV4l2Grabber(options.camera), options.camera);
  }
  status_.SetState(fusionloc::status_t::LEVEL_STARTING, "starting");
  start_monotonic_ = MonotonicUtime();
}

StereoDriverNode::StereoDriverNode(const StereoDriverOptions& options,
                                   std::unique_ptr<FrameGrabber> grabber,
                                   const RigCalibration* calibration, LcmInterface* lcm,
                                   const ChannelMap& channels)
    : options_(options),
      lcm_(lcm),
      ch_stereo_(channels(channels::kStereo)),
      ch_calibration_(channels(channels::kStereoCalibration)),
      status_(lcm, kProgram) {
  if (calibration) rectifier_ = std::make_unique<Rectifier>(*calibration);
  if (!options.capture_folder.empty()) {
    std::filesystem::create_directories(options.capture_folder + "/left");
    std::filesystem::create_directories(options.capture_folder + "/right");
  }
  camera_ = std::make_unique<SideBySideCamera>(std::move(grabber), options.camera);
  start_monotonic_ = MonotonicUtime();
}

StereoDriverNode::~StereoDriverNode() = default;

void StereoDriverNode::Capture(const StereoFrame& f) {
  const Utime now = MonotonicUtime();
  if (captured_ > 0 && now - last_capture_ < SecondsToUtime(options_.capture_period_s)) return;
  char name[32];
  std::snprintf(name, sizeof name, "%06lld.png", static_cast<long long>(captured_));
  const std::string& dir = options_.capture_folder;
  if (!cv::imwrite(dir + "/left/" + name, f.left) ||
      !cv::imwrite(dir + "/right/" + name, f.right)) {
    throw std::runtime_error("cannot write the captured pair " + std::string(name) + " in " + dir);
  }
  last_capture_ = now;
  ++captured_;
  FL_LOG(INFO) << "captured " << dir << "/{left,right}/" << name;
}

void StereoDriverNode::Publish(StereoFrame* f) {
  if (!options_.capture_folder.empty()) Capture(*f);
  if (!rectifier_) return;  // capturing only
  if (!calibration_sent_ ||
      (options_.calibration_period_s > 0 &&
       f->utime - last_calibration_ >= SecondsToUtime(options_.calibration_period_s))) {
    lcm_->Publish(ch_calibration_, CalibrationToLcm(rectifier_->camera(), f->utime), f->utime);
    calibration_sent_ = true;
    last_calibration_ = f->utime;
  }
  if (options_.gray && f->left.channels() == 3) {
    cv::cvtColor(f->left, f->left, cv::COLOR_BGR2GRAY);
    cv::cvtColor(f->right, f->right, cv::COLOR_BGR2GRAY);
  }
  cv::Mat l, r;
  try {
    rectifier_->Rectify(f->left, f->right, &l, &r);
  } catch (const std::invalid_argument& e) {
    status_.CountDropped(f->name + ": " + e.what());
    return;
  }
  lcm_->Publish(ch_stereo_, PairToLcm(l, r, f->utime), f->utime);
  ++published_;
  status_.CountOut();
}

bool StereoDriverNode::Step() {
  StereoFrame f;
  bool got = false;
  if (folder_) {
    if (options_.realtime) {  // pace: pair k is due at start + k / rate in wall time
      const Utime due =
          start_monotonic_ +
          (folder_->FrameUtime(folder_->played() + folder_->unreadable()) - folder_->FrameUtime(0));
      const Utime wait = due - MonotonicUtime();
      if (wait > 0) std::this_thread::sleep_for(std::chrono::microseconds(wait));
    }
    got = folder_->Next(&f);
  } else {
    got = camera_->Next(&f);
  }
  if (got) Publish(&f);
  while (lcm_->HandleSubscriptions(0) > 0) {
  }
  UpdateStatus();
  status_.Tick();
  return got;
}

void StereoDriverNode::UpdateStatus() {
  status_.Set("published", static_cast<double>(published_));
  if (!options_.capture_folder.empty()) status_.Set("captured", static_cast<double>(captured_));
  if (folder_) {
    status_.Set("unreadable", static_cast<double>(folder_->unreadable()));
    status_.Set("unpaired_skipped", static_cast<double>(folder_->pairs().unpaired.size()));
    if (!folder_->last_problem().empty()) {
      status_.SetState(fusionloc::status_t::LEVEL_WARN, folder_->last_problem());
    } else if (published_ > 0) {
      status_.SetState(fusionloc::status_t::LEVEL_OK, "playing");
    }
  } else {
    status_.Set("frames", static_cast<double>(camera_->frames()));
    status_.Set("dropped", static_cast<double>(camera_->dropped()));
    status_.Set("disconnects", static_cast<double>(camera_->disconnects()));
    status_.Set("reconnects", static_cast<double>(camera_->reconnects()));
    if (!camera_->connected()) {
      status_.SetState(fusionloc::status_t::LEVEL_ERROR, camera_->problem());
    } else if (camera_->frames() > 0) {
      status_.SetState(fusionloc::status_t::LEVEL_OK, "streaming");
    }
  }
}

int StereoDriverNode::Run() {
  while (!ShutdownRequested()) {
    if (!Step() && folder_) break;  // the folder has ended (a camera keeps trying)
  }
  status_.Tick(true);
  if (folder_) {
    FL_LOG(INFO) << "pairs published " << published_ << ", unreadable " << folder_->unreadable();
  } else {
    FL_LOG(INFO) << "pairs published " << published_ << ", dropped " << camera_->dropped()
                 << ", reconnects " << camera_->reconnects();
  }
  return 0;
}

}  // namespace fl::stereo

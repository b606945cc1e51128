// Synthetic stereo data for the stereo VO tests: a calibration, textured images of a
// fronto-parallel plane at a known disparity (exact sub-pixel shifts), squares with known
// corners, and 3D-3D correspondences from random points seen by a virtual rig under a known
// motion.
#pragma once

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/stereo_vo/local_ba.hpp"
#include "fusionloc/stereo_vo/motion.hpp"
#include "fusionloc/stereo_vo/stereo_vo.hpp"

namespace fl::test::stereo {

// Optical camera frame -> base frame (base x = camera z, y = -camera x, z = -camera y).
inline Eigen::Matrix3d RotationBaseCamera() {
  Eigen::Matrix3d r;
  r << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return r;
}

inline fl::vo::StereoCalibration TestCalibration(int width = 640, int height = 480) {
  fl::vo::StereoCalibration c;
  c.fx = c.fy = 500.0;
  c.cx = (width - 1) / 2.0;
  c.cy = (height - 1) / 2.0;
  c.baseline = 0.2;
  c.width = width;
  c.height = height;
  c.rectified = true;
  c.T_base_camera.setIdentity();
  c.T_base_camera.linear() = RotationBaseCamera();
  c.T_base_camera.translation() = Eigen::Vector3d(0.3, 0.1, 0.8);
  return c;
}

// A large random texture with corners (rectangles of random gray) and fine grain.
inline cv::Mat Texture(int width, int height, uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat tex(height, width, CV_8UC1, cv::Scalar(128));
  for (int i = 0; i < width * height / 300; ++i) {
    const int x = rng.uniform(0, width), y = rng.uniform(0, height);
    const int w = rng.uniform(4, 30), h = rng.uniform(4, 30);
    cv::rectangle(tex, cv::Rect(x, y, w, h), cv::Scalar(rng.uniform(0, 256)), cv::FILLED);
  }
  cv::Mat noise(height, width, CV_8UC1);
  rng.fill(noise, cv::RNG::UNIFORM, 0, 40);
  cv::add(tex, noise, tex);
  cv::GaussianBlur(tex, tex, cv::Size(3, 3), 0.8);
  return tex;
}

// The view of a fronto-parallel textured plane: the image is the texture translated by
// (-offset_x, -offset_y) pixels (sub-pixel, bilinear), cropped to width x height.
inline cv::Mat View(const cv::Mat& texture, double offset_x, double offset_y, int width,
                    int height) {
  cv::Mat m = (cv::Mat_<double>(2, 3) << 1, 0, -offset_x, 0, 1, -offset_y);
  cv::Mat out;
  cv::warpAffine(texture, out, m, cv::Size(width, height), cv::INTER_LINEAR,
                 cv::BORDER_REFLECT_101);
  return out;
}

// Dark squares of side_px on a light background, one per spacing_px grid cell (first at
// (spacing_px, spacing_px)), all moved by shift_x pixels; *corners gets the four corner pixels of
// every square, the only corners of the image (a straight edge is no FAST corner).
inline cv::Mat Squares(int width, int height, int side_px, int spacing_px, int shift_x,
                       std::vector<cv::Point2f>* corners) {
  cv::Mat img(height, width, CV_8UC1, cv::Scalar(200));
  corners->clear();
  for (int y = spacing_px; y + side_px + spacing_px <= height; y += spacing_px) {
    for (int x = spacing_px; x + side_px + spacing_px <= width; x += spacing_px) {
      const int x0 = x + shift_x, x1 = x0 + side_px - 1, y1 = y + side_px - 1;
      cv::rectangle(img, cv::Point(x0, y), cv::Point(x1, y1), cv::Scalar(50), cv::FILLED);
      for (const cv::Point2f c :
           {cv::Point2f(x0, y), cv::Point2f(x1, y), cv::Point2f(x0, y1), cv::Point2f(x1, y1)}) {
        corners->push_back(c);
      }
    }
  }
  // Blurred edges: FAST scores peak at the corners (sharp ones tie, and non-maximum
  // suppression would drop them all); the detections lie about 1 px inside each corner.
  cv::GaussianBlur(img, img, cv::Size(5, 5), 1.0);
  return img;
}

// Stereo pair of a plane at depth z seen from camera x position cam_x (camera frame, metres):
// left pixel u sees texture column u + fx * cam_x / z + margin; the right view is shifted by the
// disparity fx * b / z.
inline void PlanePair(const cv::Mat& texture, const fl::vo::StereoCalibration& c, double z,
                      double cam_x, double cam_y, cv::Mat* left, cv::Mat* right) {
  const double margin = 100.0;
  const double ox = margin + c.fx * cam_x / z, oy = margin + c.fy * cam_y / z;
  *left = View(texture, ox, oy, c.width, c.height);
  *right = View(texture, ox + c.fx * c.baseline / z, oy, c.width, c.height);
}

// Random points in front of the rig at a, seen by the rig at b = a * T_a_b, observed with
// Gaussian pixel noise; the first `outliers` correspondences get wrong observations at b.
// truth (optional): the true point of each correspondence in frame a.
inline std::vector<fl::vo::StereoCorrespondence> MakeCorrespondences(
    const fl::vo::StereoCamera& cam, const Eigen::Isometry3d& T_a_b, int n, int outliers,
    double noise_px, uint32_t seed, std::vector<Eigen::Vector3d>* truth = nullptr) {
  if (truth != nullptr) truth->clear();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(-8, 8), uy(-3, 2), uz(3, 40), uo(-60, 60);
  std::normal_distribution<double> noise(0.0, noise_px > 0 ? noise_px : 1.0);
  auto nz = [&]() { return noise_px > 0 ? noise(rng) : 0.0; };
  std::vector<fl::vo::StereoCorrespondence> out;
  const Eigen::Isometry3d T_b_a = T_a_b.inverse();
  while (static_cast<int>(out.size()) < n) {
    const Eigen::Vector3d p_a(ux(rng), uy(rng), uz(rng));
    Eigen::Vector3d oa, ob;
    if (!cam.Project(p_a, &oa) || !cam.Project(T_b_a * p_a, &ob)) continue;
    fl::vo::StereoCorrespondence c;
    c.obs_a = oa + Eigen::Vector3d(nz(), nz(), nz());
    c.obs_b = ob + Eigen::Vector3d(nz(), nz(), nz());
    if (static_cast<int>(out.size()) < outliers) {
      c.obs_b += Eigen::Vector3d(uo(rng), uo(rng), 0.0);
    }
    c.obs_a(2) = std::min(c.obs_a(2), c.obs_a(0) - 0.2);
    c.obs_b(2) = std::min(c.obs_b(2), c.obs_b(0) - 0.2);
    c.p_a = cam.Triangulate(c.obs_a(0), c.obs_a(1), c.obs_a(0) - c.obs_a(2));
    c.p_b = cam.Triangulate(c.obs_b(0), c.obs_b(1), c.obs_b(0) - c.obs_b(2));
    out.push_back(c);
    if (truth != nullptr) truth->push_back(p_a);
  }
  return out;
}

// Laser-like 3D measurements of the first `fraction` of the correspondences (true points with
// Gaussian depth noise depth_sigma_m along each observed pixel's ray, at a and at b), as the
// laser-aided mode gives them (PointMeasurement: m = depth * ray; lateral sigma
// 5 pixel_sigma_px depth / fx, the default laser_depth.point_lateral_sigma_px at 0.5 px).
inline fl::vo::PointMeasurements MakeLaserMeasurements(
    const fl::vo::StereoCamera& cam, const Eigen::Isometry3d& T_a_b,
    const std::vector<fl::vo::StereoCorrespondence>& corr,
    const std::vector<Eigen::Vector3d>& truth, double fraction, double depth_sigma_m,
    double pixel_sigma_px, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, depth_sigma_m);
  fl::vo::PointMeasurements out;
  out.pixel_sigma_px = pixel_sigma_px;
  out.per_correspondence.resize(corr.size());
  const Eigen::Isometry3d T_b_a = T_a_b.inverse();
  const size_t count = static_cast<size_t>(fraction * static_cast<double>(corr.size()));
  for (size_t i = 0; i < count && i < truth.size(); ++i) {
    fl::vo::PointMeasurement& m = out.per_correspondence[i];
    const auto measure = [&](const Eigen::Vector3d& obs, const Eigen::Vector3d& p_true,
                             Eigen::Vector3d* mp, Eigen::Matrix3d* W) {
      const Eigen::Vector3d ray((obs(0) - cam.cx) / cam.fx, (obs(1) - cam.cy) / cam.fy, 1.0);
      const double z = p_true.z() + noise(rng);
      *mp = z * ray;
      *W = fl::vo::PointSqrtInformation(ray, depth_sigma_m, 5.0 * pixel_sigma_px * z / cam.fx);
    };
    measure(corr[i].obs_a, truth[i], &m.m_a, &m.W_a);
    measure(corr[i].obs_b, T_b_a * truth[i], &m.m_b, &m.W_b);
    m.has_a = m.has_b = true;
  }
  return out;
}

// Translation [m] and rotation [deg] between two poses.
inline double TransError(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.translation() - b.translation()).norm();
}
inline double RotErrorDeg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return fl::RotationAngle(a.linear().transpose() * b.linear()) * 180.0 / M_PI;
}

inline Eigen::Isometry3d MakeMotion(double rx, double ry, double rz, double tx, double ty,
                                    double tz) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = (Eigen::AngleAxisd(rz, Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(ry, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(rx, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(tx, ty, tz);
  return T;
}

// A keyframe window for the local bundle adjustment: n keyframes of a rig driving forward
// (camera z) step_m per keyframe while turning yaw_step_rad (about camera y), and `points`
// random points (track id = index) observed with Gaussian pixel noise by every keyframe that
// sees them in a 640x480 image between 2 and 60 m. *truth: the true T_world_camera per keyframe
// (the first is the world frame); the window's poses are the truth.
inline std::vector<fl::vo::BaKeyframe> MakeKeyframeWindow(const fl::vo::StereoCamera& cam, int n,
                                                          int points, double step_m,
                                                          double yaw_step_rad, double noise_px,
                                                          uint32_t seed,
                                                          std::vector<Eigen::Isometry3d>* truth) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(-15, 15), uy(-3, 2), uz(3, 45);
  std::normal_distribution<double> noise(0.0, noise_px > 0 ? noise_px : 1.0);
  auto nz = [&]() { return noise_px > 0 ? noise(rng) : 0.0; };
  truth->clear();
  std::vector<fl::vo::BaKeyframe> window(static_cast<size_t>(n));
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (int k = 0; k < n; ++k) {
    truth->push_back(T);
    window[static_cast<size_t>(k)].id = k;
    window[static_cast<size_t>(k)].utime = 1000000 + k * 100000;
    window[static_cast<size_t>(k)].T_world_camera = T;
    T = T * MakeMotion(0.0, yaw_step_rad, 0.0, 0.0, 0.0, step_m);
  }
  for (int i = 0; i < points; ++i) {
    const Eigen::Vector3d p_world(ux(rng), uy(rng), uz(rng));
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector3d p_k = (*truth)[static_cast<size_t>(k)].inverse() * p_world;
      Eigen::Vector3d uvu;
      if (p_k.z() < 2.0 || p_k.z() > 60.0 || !cam.Project(p_k, &uvu)) continue;
      if (uvu(0) < 0 || uvu(0) > 639 || uvu(1) < 0 || uvu(1) > 479 || uvu(2) < 0) continue;
      fl::vo::BaObservation o;
      o.track_id = i;
      o.uvu = uvu + Eigen::Vector3d(nz(), nz(), nz());
      window[static_cast<size_t>(k)].observations.push_back(o);
    }
  }
  return window;
}

}  // namespace fl::test::stereo

#include "fusionloc/sim/top_view.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "fusionloc/sim/simulator.hpp"

namespace fl::sim {

void WriteTopView(const SimOptions& options, const std::string& png_path, double pixels_per_m) {
  SimOptions o = options;
  o.laser.enabled = false;
  o.camera.enabled = false;
  Simulator sim(o);
  const World& w = sim.world();
  const Eigen::Vector4d b = w.Bounds();
  const double margin = 1.0;
  const int width = static_cast<int>((b[2] - b[0] + 2 * margin) * pixels_per_m);
  constexpr int kLegend = 45;  // [px] white band above the map for the legend
  const int height = static_cast<int>((b[3] - b[1] + 2 * margin) * pixels_per_m) + kLegend;
  cv::Mat img(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  auto px = [&](const Eigen::Vector2d& p) {
    return cv::Point(static_cast<int>((p.x() - b[0] + margin) * pixels_per_m),
                     static_cast<int>((b[3] + margin - p.y()) * pixels_per_m) + kLegend);
  };
  // 1 m grid.
  for (double x = std::floor(b[0]); x <= b[2]; x += 1.0) {
    cv::line(img, px({x, b[1]}), px({x, b[3]}), cv::Scalar(235, 235, 235), 1);
  }
  for (double y = std::floor(b[1]); y <= b[3]; y += 1.0) {
    cv::line(img, px({b[0], y}), px({b[2], y}), cv::Scalar(235, 235, 235), 1);
  }
  for (const Wall& wall : w.walls()) {
    cv::line(img, px(wall.a), px(wall.b), cv::Scalar(0, 0, 0), 3);
  }
  for (const Box& box : w.boxes()) {
    const double c = std::cos(box.yaw), s = std::sin(box.yaw);
    std::vector<cv::Point> poly;
    for (const auto& k : {Eigen::Vector2d(1, 1), Eigen::Vector2d(-1, 1), Eigen::Vector2d(-1, -1),
                          Eigen::Vector2d(1, -1)}) {
      const Eigen::Vector2d l = k.cwiseProduct(box.half_size);
      poly.push_back(px(box.center + Eigen::Vector2d(c * l.x() - s * l.y(), s * l.x() + c * l.y())));
    }
    cv::fillConvexPoly(img, poly, cv::Scalar(60, 120, 200));
  }
  for (const Pillar& p : w.pillars()) {
    cv::circle(img, px(p.center), std::max(1, static_cast<int>(p.radius * pixels_per_m)),
               cv::Scalar(40, 160, 40), cv::FILLED);
  }
  const auto& route = w.route();
  for (size_t i = 0; i < route.size(); ++i) {
    cv::line(img, px(route[i]), px(route[(i + 1) % route.size()]), cv::Scalar(200, 200, 200), 5);
  }
  SimFrame f;
  std::vector<cv::Point> truth, odom;
  while (sim.Step(&f)) {
    truth.push_back(px(f.T_world_base.translation()));
    // Odometry starts at the start pose: draw it in the world frame.
    const Pose2 start(route[0].x(), route[0].y(), 0.0);
    const Eigen::Vector2d d = route[1] - route[0];
    const Pose2 T_world_odom(start.x, start.y, std::atan2(d.y(), d.x()));
    odom.push_back(px(T_world_odom * f.T_odom_base.translation()));
  }
  cv::polylines(img, odom, false, cv::Scalar(0, 0, 220), 1, cv::LINE_AA);
  cv::polylines(img, truth, false, cv::Scalar(200, 60, 0), 2, cv::LINE_AA);
  cv::circle(img, px(route[0]), 6, cv::Scalar(0, 0, 0), 2);
  cv::putText(img, "world '" + w.name() + "': walls black, boxes orange, pillars green, route grey,",
              cv::Point(10, 20), cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 1);
  cv::putText(img, "driven truth blue, noisy odometry red; 1 m grid; circle = start",
              cv::Point(10, 38), cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 1);
  if (!cv::imwrite(png_path, img)) {
    throw std::runtime_error("cannot write top view '" + png_path +
                             "'; check that the folder exists and is writable");
  }
}

void WriteSnapshot(const SimOptions& options, double time_s, const std::string& prefix) {
  SimOptions o = options;
  o.laser.enabled = false;
  o.camera.enabled = false;
  Simulator sim(o);
  const int64_t target = std::llround(time_s / o.step_s);
  if (target < 0 || target > o.steps()) {
    throw std::runtime_error("snapshot time " + std::to_string(time_s) +
                             " s is outside the simulation [0, " +
                             std::to_string(o.duration_s) + "] s");
  }
  SimFrame f;
  while (sim.Step(&f) && f.step < target) {
  }
  Rng rng(Hash3(static_cast<uint64_t>(o.seed), 99, target));
  for (CameraModel::Eye eye : {CameraModel::kLeft, CameraModel::kRight}) {
    std::vector<uint8_t> pixels;
    sim.camera().Render(sim.world(), f.T_world_base, eye, &rng, &pixels);
    const cv::Mat img(o.camera.height, o.camera.width, CV_8UC1, pixels.data());
    const std::string path = prefix + (eye == CameraModel::kLeft ? "_left.png" : "_right.png");
    if (!cv::imwrite(path, img)) {
      throw std::runtime_error("cannot write '" + path + "'; check that the folder exists");
    }
  }
}

}  // namespace fl::sim

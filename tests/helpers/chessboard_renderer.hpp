// Synthetic chessboard views through a pinhole + distortion camera (OpenCV's model), for the
// stereo rectification and calibration tests. Each output pixel averages s x s sub-pixel
// samples; a sample's ray (cv::undistortPoints, computed once per camera) is intersected with
// the board plane and coloured by the square it hits, so the corners sit where
// cv::projectPoints puts them.
#pragma once

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace fl::test {

struct Chessboard {
  int inner_cols = 9;     // inner corners along the board's x
  int inner_rows = 6;     // inner corners along y
  double square = 0.035;  // [m]
  // Inner corners in the board frame (z = 0), row by row.
  std::vector<cv::Point3f> Corners() const {
    std::vector<cv::Point3f> c;
    for (int r = 1; r <= inner_rows; ++r) {
      for (int k = 1; k <= inner_cols; ++k) {
        c.emplace_back(static_cast<float>(k * square), static_cast<float>(r * square), 0.f);
      }
    }
    return c;
  }
};

class ChessboardCamera {
 public:
  ChessboardCamera(cv::Mat K, cv::Mat D, cv::Size size, int supersample = 4)
      : K_(std::move(K)), D_(std::move(D)), size_(size), s_(supersample) {
    const int W = size.width * s_, H = size.height * s_;
    std::vector<cv::Point2f> px;
    px.reserve(static_cast<size_t>(W) * H);
    for (int V = 0; V < H; ++V) {
      for (int U = 0; U < W; ++U) {
        px.emplace_back((U + 0.5f) / s_ - 0.5f, (V + 0.5f) / s_ - 0.5f);
      }
    }
    cv::undistortPoints(px, rays_, K_, D_);  // normalised (x, y) of every sample
  }

  // The board seen with board->camera rotation R_cb and translation t_cb [m]: 8-bit gray,
  // black and white squares, a one-square white border, gray background.
  cv::Mat Render(const Chessboard& b, const cv::Matx33d& R_cb, const cv::Vec3d& t_cb) const {
    const int W = size_.width * s_, H = size_.height * s_;
    cv::Mat hi(H, W, CV_32F);
    const cv::Matx33d Rt = R_cb.t();
    const cv::Vec3d q = Rt * t_cb;
    const double x_max = (b.inner_cols + 1) * b.square, y_max = (b.inner_rows + 1) * b.square;
    for (int i = 0; i < W * H; ++i) {
      const cv::Point2f& n = rays_[static_cast<size_t>(i)];
      const cv::Vec3d r = Rt * cv::Vec3d(n.x, n.y, 1.0);
      float value = 100.f;  // background
      if (std::abs(r[2]) > 1e-12) {
        const double lambda = q[2] / r[2];
        if (lambda > 0) {
          const double X = lambda * r[0] - q[0], Y = lambda * r[1] - q[1];
          if (X >= -b.square && X <= x_max + b.square && Y >= -b.square && Y <= y_max + b.square) {
            value = 255.f;  // border
            if (X >= 0 && X < x_max && Y >= 0 && Y < y_max) {
              const int ix = static_cast<int>(std::floor(X / b.square));
              const int iy = static_cast<int>(std::floor(Y / b.square));
              value = ((ix + iy) % 2 == 0) ? 20.f : 235.f;
            }
          }
        }
      }
      hi.at<float>(i / W, i % W) = value;
    }
    cv::Mat lo, out;
    cv::resize(hi, lo, size_, 0, 0, cv::INTER_AREA);
    lo.convertTo(out, CV_8U);
    return out;
  }

  // Where cv::projectPoints puts the board's inner corners.
  std::vector<cv::Point2f> Project(const Chessboard& b, const cv::Matx33d& R_cb,
                                   const cv::Vec3d& t_cb) const {
    cv::Mat rvec;
    cv::Rodrigues(cv::Mat(R_cb), rvec);
    std::vector<cv::Point2f> out;
    cv::projectPoints(b.Corners(), rvec, cv::Mat(t_cb), K_, D_, out);
    return out;
  }

 private:
  cv::Mat K_, D_;
  cv::Size size_;
  int s_;
  std::vector<cv::Point2f> rays_;
};

// Rotation from a Rodrigues vector.
inline cv::Matx33d Rot(double rx, double ry, double rz) {
  cv::Matx33d R;
  cv::Rodrigues(cv::Vec3d(rx, ry, rz), R);
  return R;
}

}  // namespace fl::test

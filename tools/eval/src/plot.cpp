#include "fusionloc/eval/plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace fl::eval {
namespace {

constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;
constexpr double kTickFontScale = 0.45;
constexpr double kLabelFontScale = 0.55;
constexpr double kTitleFontScale = 0.7;
const cv::Scalar kInk(40, 40, 40);
const cv::Scalar kGridInk(225, 225, 225);
const cv::Scalar kZeroInk(150, 150, 150);

cv::Scalar ToScalar(const Color& c) { return cv::Scalar(c.b, c.g, c.r); }  // OpenCV is BGR

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void Add(double v) {
    if (!std::isfinite(v)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  bool valid() const { return lo <= hi; }
  double span() const { return hi - lo; }
  double center() const { return 0.5 * (lo + hi); }
};

// Widens an empty or degenerate range and adds a margin on each side.
Range Padded(Range r, double fraction, double min_half_span) {
  if (r.span() < 2 * min_half_span * 1e-6) {
    const double c = r.center();
    const double h = std::max(min_half_span, std::fabs(c) * 0.1);
    r.lo = c - h;
    r.hi = c + h;
  }
  const double pad = r.span() * fraction;
  r.lo -= pad;
  r.hi += pad;
  return r;
}

double NiceStep(double raw) {
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double norm = raw / mag;
  const double nice = norm < 1.5 ? 1.0 : norm < 3.0 ? 2.0 : norm < 7.0 ? 5.0 : 10.0;
  return nice * mag;
}

std::vector<double> Ticks(const Range& r, int target, double* step_out) {
  const double step = NiceStep(r.span() / target);
  *step_out = step;
  std::vector<double> ticks;
  for (double v = std::ceil(r.lo / step) * step; v <= r.hi + 1e-9 * step; v += step) {
    ticks.push_back(std::fabs(v) < 1e-9 * step ? 0.0 : v);
  }
  return ticks;
}

std::string TickLabel(double v, double step) {
  const int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", decimals, v);
  return buf;
}

cv::Size TextSize(const std::string& text, double scale, int* baseline = nullptr) {
  int base = 0;
  const cv::Size s = cv::getTextSize(text, kFont, scale, 1, &base);
  if (baseline) *baseline = base;
  return s;
}

void PutText(cv::Mat& img, const std::string& text, cv::Point org, double scale,
             const cv::Scalar& color = kInk, int thickness = 1) {
  cv::putText(img, text, org, kFont, scale, color, thickness, cv::LINE_AA);
}

// Text rotated 90 degrees counter-clockwise, centred vertically at `center_y`, left edge at x.
void PutVerticalText(cv::Mat& img, const std::string& text, int x, int center_y, double scale) {
  int base = 0;
  const cv::Size s = TextSize(text, scale, &base);
  cv::Mat patch(s.height + base + 4, s.width + 4, CV_8UC3, cv::Scalar(255, 255, 255));
  PutText(patch, text, cv::Point(2, s.height + 2), scale);
  cv::Mat rotated;
  cv::rotate(patch, rotated, cv::ROTATE_90_COUNTERCLOCKWISE);
  cv::Rect dst(x, center_y - rotated.rows / 2, rotated.cols, rotated.rows);
  dst &= cv::Rect(0, 0, img.cols, img.rows);
  if (dst.area() <= 0) return;
  rotated(cv::Rect(0, 0, dst.width, dst.height)).copyTo(img(dst));
}

// Maps data coordinates into a pixel rectangle (y up).
struct Frame {
  cv::Rect rect;
  Range x, y;
  cv::Point2d ToPx(double vx, double vy) const {
    return {rect.x + (vx - x.lo) / x.span() * rect.width,
            rect.y + rect.height - (vy - y.lo) / y.span() * rect.height};
  }
};

cv::Point Shifted(const cv::Point2d& p) {  // sub-pixel coordinates for anti-aliased drawing
  return cv::Point(static_cast<int>(std::lround(p.x * 16)),
                   static_cast<int>(std::lround(p.y * 16)));
}

void Line(cv::Mat& img, const cv::Point2d& a, const cv::Point2d& b, const cv::Scalar& color,
          int thickness) {
  cv::line(img, Shifted(a), Shifted(b), color, thickness, cv::LINE_AA, 4);
}

// Grid, ticks with numbers, frame and axis labels.
void DrawAxes(cv::Mat& img, const Frame& f, const std::string& x_label, const std::string& y_label,
              bool x_numbers, bool zero_line) {
  double xstep = 1, ystep = 1;
  const auto xticks = Ticks(f.x, std::max(3, f.rect.width / 110), &xstep);
  const auto yticks = Ticks(f.y, std::max(3, f.rect.height / 60), &ystep);
  for (double v : xticks) {
    const double px = f.ToPx(v, f.y.lo).x;
    cv::line(img, cv::Point(static_cast<int>(px), f.rect.y),
             cv::Point(static_cast<int>(px), f.rect.y + f.rect.height), kGridInk, 1);
  }
  for (double v : yticks) {
    const double py = f.ToPx(f.x.lo, v).y;
    cv::line(img, cv::Point(f.rect.x, static_cast<int>(py)),
             cv::Point(f.rect.x + f.rect.width, static_cast<int>(py)), kGridInk, 1);
  }
  if (zero_line && f.y.lo < 0 && f.y.hi > 0) {
    const int py = static_cast<int>(f.ToPx(f.x.lo, 0.0).y);
    cv::line(img, cv::Point(f.rect.x, py), cv::Point(f.rect.x + f.rect.width, py), kZeroInk, 1);
  }
  cv::rectangle(img, f.rect, kInk, 1);
  const int bottom = f.rect.y + f.rect.height;
  for (double v : xticks) {
    const int px = static_cast<int>(f.ToPx(v, f.y.lo).x);
    cv::line(img, cv::Point(px, bottom), cv::Point(px, bottom + 5), kInk, 1);
    if (x_numbers) {
      const std::string t = TickLabel(v, xstep);
      const cv::Size s = TextSize(t, kTickFontScale);
      PutText(img, t, cv::Point(px - s.width / 2, bottom + 8 + s.height), kTickFontScale);
    }
  }
  int max_label_w = 0;
  for (double v : yticks) {
    const int py = static_cast<int>(f.ToPx(f.x.lo, v).y);
    cv::line(img, cv::Point(f.rect.x - 5, py), cv::Point(f.rect.x, py), kInk, 1);
    const std::string t = TickLabel(v, ystep);
    const cv::Size s = TextSize(t, kTickFontScale);
    max_label_w = std::max(max_label_w, s.width);
    PutText(img, t, cv::Point(f.rect.x - 8 - s.width, py + s.height / 2), kTickFontScale);
  }
  if (x_numbers && !x_label.empty()) {
    const cv::Size s = TextSize(x_label, kLabelFontScale);
    PutText(img, x_label, cv::Point(f.rect.x + f.rect.width / 2 - s.width / 2, bottom + 44),
            kLabelFontScale);
  }
  if (!y_label.empty()) {
    const int x =
        std::max(2, f.rect.x - 14 - max_label_w - TextSize(y_label, kLabelFontScale).height - 6);
    PutVerticalText(img, y_label, x, f.rect.y + f.rect.height / 2, kLabelFontScale);
  }
}

void DrawLegend(cv::Mat& img, const cv::Rect& rect,
                const std::vector<std::pair<std::string, Color>>& entries,
                const std::string& footnote = "") {
  if (entries.empty()) return;
  int w = 0;
  for (const auto& e : entries) w = std::max(w, TextSize(e.first, kTickFontScale).width);
  if (!footnote.empty()) w = std::max(w - 34, TextSize(footnote, kTickFontScale).width - 34);
  const int row = 20;
  const int rows = static_cast<int>(entries.size()) + (footnote.empty() ? 0 : 1);
  const cv::Rect box(rect.x + rect.width - w - 54, rect.y + 8, w + 46, rows * row + 10);
  cv::rectangle(img, box, cv::Scalar(255, 255, 255), cv::FILLED);
  cv::rectangle(img, box, cv::Scalar(180, 180, 180), 1);
  for (size_t i = 0; i < entries.size(); ++i) {
    const int y = box.y + 15 + static_cast<int>(i) * row;
    cv::line(img, cv::Point(box.x + 8, y), cv::Point(box.x + 32, y), ToScalar(entries[i].second), 2,
             cv::LINE_AA);
    PutText(img, entries[i].first, cv::Point(box.x + 38, y + 5), kTickFontScale);
  }
  if (!footnote.empty()) {
    PutText(img, footnote, cv::Point(box.x + 8, box.y + 15 + (rows - 1) * row + 5), kTickFontScale,
            cv::Scalar(90, 90, 90));
  }
}

void DrawTitle(cv::Mat& img, const std::string& title) {
  if (title.empty()) return;
  const cv::Size s = TextSize(title, kTitleFontScale);
  PutText(img, title, cv::Point(img.cols / 2 - s.width / 2, 28), kTitleFontScale, kInk, 2);
}

void WritePng(const cv::Mat& img, const std::string& path) {
  std::vector<uchar> buffer;
  if (!cv::imencode(".png", img, buffer)) throw EvalError("PNG encoding failed for '" + path + "'");
  const std::string tmp = path + ".partial";
  {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) {
      throw EvalError("cannot write plot '" + path +
                      "': does the folder exist and is it writable?");
    }
    out.write(reinterpret_cast<const char*>(buffer.data()),
              static_cast<std::streamsize>(buffer.size()));
    if (!out.good()) throw EvalError("error writing plot '" + tmp + "' (disk full?)");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw EvalError("cannot rename '" + tmp + "' to '" + path + "'");
  }
}

// Draws a polyline through finite points, breaking at non-finite ones.
void Polyline(cv::Mat& img, const Frame& f, const std::vector<double>& xs,
              const std::vector<double>& ys, const cv::Scalar& color, int thickness) {
  bool have_prev = false;
  cv::Point2d prev;
  for (size_t i = 0; i < xs.size() && i < ys.size(); ++i) {
    if (!std::isfinite(xs[i]) || !std::isfinite(ys[i])) {
      have_prev = false;
      continue;
    }
    const cv::Point2d p = f.ToPx(xs[i], ys[i]);
    if (have_prev) {
      Line(img, prev, p, color, thickness);
    } else if (i + 1 >= xs.size() || !std::isfinite(ys[i + 1])) {
      cv::circle(img, Shifted(p), thickness * 16, color, cv::FILLED, cv::LINE_AA, 4);
    }
    prev = p;
    have_prev = true;
  }
}

}  // namespace

Color PlotColor(size_t index) {
  static const Color kCycle[] = {kPlotBlue,   kPlotOrange, kPlotGreen, kPlotRed,
                                 kPlotPurple, kPlotGray,   kPlotBlack};
  return kCycle[index % (sizeof(kCycle) / sizeof(kCycle[0]))];
}

void PlotTrajectoriesTopView(const std::string& png_path,
                             const std::vector<TrajectoryCurve>& curves,
                             const TopViewOptions& options) {
  if (options.width_px < 300 || options.height_px < 250) {
    throw EvalError("top-view plot size must be at least 300 x 250 pixels");
  }
  if (options.plane != "xy" && options.plane != "xz") {
    throw EvalError("top-view plane '" + options.plane + "' unknown; use xy or xz");
  }
  const int vert = options.plane == "xy" ? 1 : 2;  // index of the vertical plot axis
  Range xr, yr;
  for (const auto& c : curves) {
    for (const auto& p : c.trajectory) {
      if (!p.T_world_base.translation().allFinite()) continue;
      xr.Add(p.T_world_base.translation().x());
      yr.Add(p.T_world_base.translation()(vert));
    }
  }
  if (!xr.valid()) {
    throw EvalError("nothing to plot in '" + png_path + "': the trajectories have no finite poses");
  }
  const BackgroundGrid* bg = options.background;
  if (bg && vert != 1) throw EvalError("a background grid needs the xy plane");
  if (bg) {
    if (bg->width <= 0 || bg->height <= 0 || !(bg->resolution > 0) ||
        bg->cells.size() != static_cast<size_t>(bg->width) * static_cast<size_t>(bg->height)) {
      throw EvalError("background grid for '" + png_path +
                      "' is inconsistent (width*height != cells or resolution <= 0)");
    }
    xr.Add(bg->origin_x);
    xr.Add(bg->origin_x + bg->width * bg->resolution);
    yr.Add(bg->origin_y);
    yr.Add(bg->origin_y + bg->height * bg->resolution);
  }
  cv::Mat img(options.height_px, options.width_px, CV_8UC3, cv::Scalar(255, 255, 255));
  Frame f;
  f.rect = cv::Rect(95, 45, options.width_px - 95 - 25, options.height_px - 45 - 70);
  xr = Padded(xr, 0.05, 0.5);
  yr = Padded(yr, 0.05, 0.5);
  // Equal axes: the same metres per pixel in x and y.
  const double mpp = std::max(xr.span() / f.rect.width, yr.span() / f.rect.height);
  f.x.lo = xr.center() - 0.5 * mpp * f.rect.width;
  f.x.hi = xr.center() + 0.5 * mpp * f.rect.width;
  f.y.lo = yr.center() - 0.5 * mpp * f.rect.height;
  f.y.hi = yr.center() + 0.5 * mpp * f.rect.height;

  if (bg) {
    for (int py = f.rect.y; py < f.rect.y + f.rect.height; ++py) {
      auto* row = img.ptr<cv::Vec3b>(py);
      const double wy = f.y.hi - (py + 0.5 - f.rect.y) * mpp;
      const double r = std::floor((wy - bg->origin_y) / bg->resolution);
      if (r < 0 || r >= bg->height) continue;
      for (int px = f.rect.x; px < f.rect.x + f.rect.width; ++px) {
        const double wx = f.x.lo + (px + 0.5 - f.rect.x) * mpp;
        const double c = std::floor((wx - bg->origin_x) / bg->resolution);
        if (c < 0 || c >= bg->width) continue;
        const int v = bg->cells[static_cast<size_t>(r) * static_cast<size_t>(bg->width) +
                                static_cast<size_t>(c)];
        uchar g = 230;  // unknown
        if (v >= 0) g = static_cast<uchar>(255 - std::min(100, v) * 170 / 100);
        row[px] = cv::Vec3b(g, g, g);
      }
    }
  }
  DrawAxes(img, f, "x [m]", vert == 1 ? "y [m]" : "z [m]", true, false);
  std::vector<std::pair<std::string, Color>> legend;
  for (const auto& c : curves) {
    std::vector<double> xs, ys;
    for (const auto& p : c.trajectory) {
      const bool ok = p.T_world_base.translation().allFinite();
      xs.push_back(ok ? p.T_world_base.translation().x() : std::nan(""));
      ys.push_back(ok ? p.T_world_base.translation()(vert) : std::nan(""));
    }
    Polyline(img, f, xs, ys, ToScalar(c.color), 2);
    legend.emplace_back(c.name, c.color);
  }
  // Start (circle) and end (square) markers.
  for (const auto& c : curves) {
    const StampedPose* first = nullptr;
    const StampedPose* last = nullptr;
    for (const auto& p : c.trajectory) {
      if (!p.T_world_base.translation().allFinite()) continue;
      if (!first) first = &p;
      last = &p;
    }
    if (!first) continue;
    const cv::Point2d a =
        f.ToPx(first->T_world_base.translation().x(), first->T_world_base.translation()(vert));
    const cv::Point2d b =
        f.ToPx(last->T_world_base.translation().x(), last->T_world_base.translation()(vert));
    cv::circle(img, cv::Point(static_cast<int>(a.x), static_cast<int>(a.y)), 6, ToScalar(c.color),
               2, cv::LINE_AA);
    cv::rectangle(img, cv::Rect(static_cast<int>(b.x) - 5, static_cast<int>(b.y) - 5, 11, 11),
                  ToScalar(c.color), 2, cv::LINE_AA);
  }
  cv::rectangle(img, f.rect, kInk, 1);
  DrawLegend(img, f.rect, legend, "o start   [] end");
  // Scale bar, bottom left inside the plot.
  const double bar_m = NiceStep(0.2 * f.x.span());
  const int bar_px = static_cast<int>(std::lround(bar_m / mpp));
  const cv::Point s0(f.rect.x + 15, f.rect.y + f.rect.height - 18);
  const cv::Point s1(s0.x + bar_px, s0.y);
  cv::rectangle(img, cv::Rect(s0.x - 6, s0.y - 24, bar_px + 12, 32), cv::Scalar(255, 255, 255),
                cv::FILLED);
  cv::line(img, s0, s1, kInk, 2);
  cv::line(img, s0 + cv::Point(0, -5), s0 + cv::Point(0, 5), kInk, 2);
  cv::line(img, s1 + cv::Point(0, -5), s1 + cv::Point(0, 5), kInk, 2);
  const std::string bar_text = TickLabel(bar_m, bar_m) + " m";
  PutText(img, bar_text,
          cv::Point(s0.x + bar_px / 2 - TextSize(bar_text, kTickFontScale).width / 2, s0.y - 9),
          kTickFontScale);
  DrawTitle(img, options.title.empty() ? "Trajectories (top view)" : options.title);
  WritePng(img, png_path);
}

void PlotSeries(const std::string& png_path, const std::string& title, const std::string& x_label,
                const std::vector<Panel>& panels, int width_px, int panel_height_px) {
  if (panels.empty()) throw EvalError("PlotSeries('" + png_path + "'): no panels to draw");
  if (width_px < 300 || panel_height_px < 100) {
    throw EvalError("series plot must be at least 300 px wide with panels >= 100 px high");
  }
  Range xr;
  for (const auto& p : panels) {
    for (const auto& c : p.curves) {
      if (c.x.size() != c.y.size()) {
        throw EvalError("PlotSeries('" + png_path + "'): curve '" + c.name + "' has " +
                        std::to_string(c.x.size()) + " x values but " + std::to_string(c.y.size()) +
                        " y values");
      }
      for (size_t i = 0; i < c.x.size(); ++i) {
        if (std::isfinite(c.y[i])) xr.Add(c.x[i]);
      }
    }
  }
  if (!xr.valid()) throw EvalError("nothing to plot in '" + png_path + "': no finite values");
  xr = Padded(xr, 0.0, 0.5);
  const int top = 45, gap = 18, bottom = 60;
  const int n = static_cast<int>(panels.size());
  cv::Mat img(top + n * panel_height_px + (n - 1) * gap + bottom, width_px, CV_8UC3,
              cv::Scalar(255, 255, 255));
  for (int k = 0; k < n; ++k) {
    const Panel& panel = panels[static_cast<size_t>(k)];
    Range yr;
    for (const auto& c : panel.curves) {
      for (size_t i = 0; i < c.y.size(); ++i) {
        if (std::isfinite(c.x[i])) yr.Add(c.y[i]);
      }
    }
    if (!yr.valid()) {
      yr.lo = -1;
      yr.hi = 1;
    }
    Frame f;
    f.rect = cv::Rect(95, top + k * (panel_height_px + gap), width_px - 95 - 25, panel_height_px);
    f.x = xr;
    f.y = Padded(yr, 0.08, 1e-3);
    DrawAxes(img, f, x_label, panel.y_label, k == n - 1, true);
    std::vector<std::pair<std::string, Color>> legend;
    for (const auto& c : panel.curves) {
      Polyline(img, f, c.x, c.y, ToScalar(c.color), 2);
      legend.emplace_back(c.name, c.color);
    }
    cv::rectangle(img, f.rect, kInk, 1);
    if (legend.size() > 1) DrawLegend(img, f.rect, legend);
  }
  DrawTitle(img, title);
  WritePng(img, png_path);
}

void PlotAteErrors(const std::string& png_path, const AteResult& ate, const std::string& title,
                   const std::string& est_name, const std::string& plane) {
  if (ate.utimes.empty()) throw EvalError("no ATE pairs to plot in '" + png_path + "'");
  if (plane != "xy" && plane != "xz") {
    throw EvalError("error-plot plane '" + plane + "' unknown; use xy or xz");
  }
  std::vector<double> t;
  for (Utime u : ate.utimes) t.push_back(UtimeToSeconds(u - ate.utimes.front()));
  auto panel = [&](const std::string& label, const std::vector<double>& y) {
    return Panel{label, {SeriesCurve{est_name, t, y, kPlotBlue}}};
  };
  if (plane == "xy") {
    PlotSeries(png_path, title, "time since start [s]",
               {panel("x error [m]", ate.err_x_m), panel("y error [m]", ate.err_y_m),
                panel("heading error [deg]", ate.err_yaw_deg)});
    return;
  }
  // Heading in the x-z plane: direction of the body z axis, atan2(R02, R22).
  std::vector<double> heading;
  for (size_t i = 0; i < ate.est_aligned.size() && i < ate.ref_matched.size(); ++i) {
    const Eigen::Matrix3d& Re = ate.est_aligned[i].T_world_base.linear();
    const Eigen::Matrix3d& Rr = ate.ref_matched[i].T_world_base.linear();
    const double d = std::atan2(Re(0, 2), Re(2, 2)) - std::atan2(Rr(0, 2), Rr(2, 2));
    heading.push_back(std::remainder(d, 2.0 * M_PI) * 180.0 / M_PI);
  }
  PlotSeries(png_path, title, "time since start [s]",
             {panel("x error [m]", ate.err_x_m), panel("z error [m]", ate.err_z_m),
              panel("heading error (x-z) [deg]", heading)});
}

}  // namespace fl::eval

#include "capture/colour_calibration.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <opencv2/mcc.hpp>

#include "capture/opencv_bridge.h"
#include "core/error.h"

namespace u3mscan {
namespace {

constexpr int kColumns = 6;
constexpr int kRows = 4;
constexpr double kSampledFraction = 0.5;  // the central half of a patch's pitch, clear of its edges

// Mean of the frame over the quadrilateral `corners` (px), 3 channels; the mask covers only the
// quadrilateral's bounding box, so a patch costs its own size, not the frame's.
Rgb MeanOverQuad(const Image& frame, const std::array<cv::Point2f, 4>& corners) {
  std::vector<cv::Point> polygon;
  for (const auto& c : corners) polygon.emplace_back(static_cast<int>(std::lround(c.x)), static_cast<int>(std::lround(c.y)));
  const cv::Rect box = cv::boundingRect(polygon) & cv::Rect(0, 0, frame.width(), frame.height());
  Rgb mean{};
  if (box.empty()) return mean;
  for (auto& p : polygon) p -= box.tl();
  cv::Mat mask = cv::Mat::zeros(box.size(), CV_8U);
  cv::fillConvexPoly(mask, polygon, cv::Scalar(255));
  for (int c = 0; c < 3; ++c) mean[c] = cv::mean(internal::PlaneView(frame, c)(box), mask)[0];
  return mean;
}

bool Inside(const Image& frame, const cv::Point2f& p) {
  return p.x >= 0 && p.y >= 0 && p.x <= frame.width() - 1 && p.y <= frame.height() - 1;
}

}  // namespace

const std::array<Rgb, 24>& ClassicChartLinearSrgb() {
  // Published 8-bit sRGB of the classic 24-patch chart, linearised once.
  static const std::array<Rgb, 24> kChart = [] {
    constexpr int kSrgb8[24][3] = {{115, 82, 68},   {194, 150, 130}, {98, 122, 157},  {87, 108, 67},
                                   {133, 128, 177}, {103, 189, 170}, {214, 126, 44},  {80, 91, 166},
                                   {193, 90, 99},   {94, 60, 108},   {157, 188, 64},  {224, 163, 46},
                                   {56, 61, 150},   {70, 148, 73},   {175, 54, 60},   {231, 199, 31},
                                   {187, 86, 149},  {8, 133, 161},   {243, 243, 242}, {200, 200, 200},
                                   {160, 160, 160}, {122, 122, 121}, {85, 85, 85},    {52, 52, 52}};
    std::array<Rgb, 24> chart{};
    for (int i = 0; i < 24; ++i) {
      for (int c = 0; c < 3; ++c) chart[i][c] = SrgbToLinear(kSrgb8[i][c] / 255.0);
    }
    return chart;
  }();
  return kChart;
}

std::vector<ChartPatch> MeasureChartAtLayout(const Image& frame_rgb, const CameraModel& camera,
                                             const ChartLayout& layout, const std::string& frame_file) {
  std::vector<ChartPatch> patches;
  const double half = 0.5 * kSampledFraction * layout.patch_pitch_mm;
  for (int row = 0; row < kRows; ++row) {
    for (int col = 0; col < kColumns; ++col) {
      const double x = layout.centre_mm.x() + (col - 0.5 * (kColumns - 1)) * layout.patch_pitch_mm;
      const double y = layout.centre_mm.y() + (0.5 * (kRows - 1) - row) * layout.patch_pitch_mm;
      std::array<cv::Point2f, 4> quad;
      const double offsets[4][2] = {{-half, -half}, {half, -half}, {half, half}, {-half, half}};
      for (int k = 0; k < 4; ++k) {
        const Eigen::Vector2d p = camera.Project(Eigen::Vector3d(x + offsets[k][0], y + offsets[k][1], 0.0));
        quad[k] = cv::Point2f(static_cast<float>(p.x()), static_cast<float>(p.y()));
        if (!Inside(frame_rgb, quad[k])) {
          throw InputError(frame_file, "",
                           "a colour chart whose patch " + std::to_string(row * kColumns + col + 1) +
                               " lies in the camera's view at the known layout (centre " +
                               std::to_string(layout.centre_mm.x()) + ", " + std::to_string(layout.centre_mm.y()) +
                               " mm, pitch " + std::to_string(layout.patch_pitch_mm) + " mm)");
        }
      }
      ChartPatch patch;
      patch.centre_px = camera.Project(Eigen::Vector3d(x, y, 0.0));
      patch.mean_rgb = MeanOverQuad(frame_rgb, quad);
      patches.push_back(patch);
    }
  }
  return patches;
}

double FindChartPitchMm(const Image& frame_rgb, const CameraModel& camera, const Eigen::Vector2d& centre_mm) {
  const Eigen::Vector3d centre(centre_mm.x(), centre_mm.y(), 0.0);
  const double camera_pitch = camera.PitchOnPlaneMm(centre);
  if (!(camera_pitch > 0.0)) return 0.0;
  const double min_pitch = 6.0 * camera_pitch;
  const double max_pitch = camera_pitch * std::max(camera.width, camera.height) / kColumns;
  const auto& reference = ClassicChartLinearSrgb();
  const std::vector<Rgb> reference_list(reference.begin(), reference.end());
  // Score: the linear RGB residual of the 3x3 fit; infinite when a patch leaves the view.
  auto score = [&](double pitch) {
    try {
      const auto patches = MeasureChartAtLayout(frame_rgb, camera, {centre_mm, pitch}, "");
      std::vector<Rgb> measured;
      for (const auto& p : patches) measured.push_back(p.mean_rgb);
      return FitColourCorrection(measured, reference_list).rms_rgb_after;
    } catch (const InputError&) {
      return 1e300;
    }
  };
  double best_pitch = 0.0, best_score = 1e300;
  for (double pitch = min_pitch; pitch <= max_pitch; pitch *= 1.03) {
    const double s = score(pitch);
    if (s < best_score) best_score = s, best_pitch = pitch;
  }
  if (best_pitch == 0.0) return 0.0;
  // Every pitch that keeps the sampled centres inside their patches fits equally well (a plateau
  // some +-7 % wide); the true pitch is its middle. Fine scan, then the plateau's geometric centre.
  std::vector<std::pair<double, double>> fine;
  for (double pitch = best_pitch / 1.2; pitch <= best_pitch * 1.2; pitch *= 1.004) fine.emplace_back(pitch, score(pitch));
  const auto best = std::min_element(fine.begin(), fine.end(), [](const auto& a, const auto& b) { return a.second < b.second; });
  const double threshold = 1.5 * best->second + 1e-4;
  auto lo = best, hi = best;
  while (lo != fine.begin() && std::prev(lo)->second <= threshold) --lo;
  while (std::next(hi) != fine.end() && std::next(hi)->second <= threshold) ++hi;
  return std::sqrt(lo->first * hi->first);
}

std::optional<std::vector<ChartPatch>> MeasureChartWithMcc(const Image& frame_rgb) {
  // mcc wants an 8-bit BGR photograph: sRGB-encode, white at the 99th percentile.
  cv::Mat grey = internal::GreyCopy(frame_rgb);
  const double white = std::max(1e-6, internal::Quantile(grey, 0.99));
  std::vector<cv::Mat> bgr = {internal::ToDisplay8(internal::PlaneView(frame_rgb, 2), white),
                              internal::ToDisplay8(internal::PlaneView(frame_rgb, 1), white),
                              internal::ToDisplay8(internal::PlaneView(frame_rgb, 0), white)};
  cv::Mat image;
  cv::merge(bgr, image);
  // The detector needs a chart of some tens of pixels a patch, not 36 megapixels: it runs on a
  // copy of at most kMccMaxSide pixels a side, and its box is scaled back (pixel centres kept).
  constexpr int kMccMaxSide = 1600;
  const double scale = std::min(1.0, static_cast<double>(kMccMaxSide) / std::max(image.cols, image.rows));
  if (scale < 1.0) cv::resize(image, image, cv::Size(), scale, scale, cv::INTER_AREA);
  auto detector = cv::mcc::CCheckerDetector::create();
  if (!detector->process(image, cv::mcc::MCC24, 1)) return std::nullopt;
  const auto checker = detector->getBestColorChecker();
  if (!checker) return std::nullopt;
  std::vector<cv::Point2f> box = checker->getBox();
  if (box.size() != 4) return std::nullopt;
  for (auto& corner : box) {
    corner = cv::Point2f(static_cast<float>((corner.x + 0.5) / scale - 0.5), static_cast<float>((corner.y + 0.5) / scale - 0.5));
  }
  // The long side of the box carries the 6 columns.
  if (cv::norm(box[1] - box[0]) < cv::norm(box[3] - box[0])) std::rotate(box.begin(), box.begin() + 1, box.end());
  const auto& reference = ClassicChartLinearSrgb();
  std::optional<std::vector<ChartPatch>> best;
  double best_residual = 1e300;
  for (int turn = 0; turn < 2; ++turn) {  // 0 and 180 degrees
    std::vector<cv::Point2f> corners = box;
    if (turn == 1) std::rotate(corners.begin(), corners.begin() + 2, corners.end());
    const std::vector<cv::Point2f> model = {{0, 0}, {kColumns, 0}, {kColumns, kRows}, {0, kRows}};
    const cv::Mat homography = cv::getPerspectiveTransform(model, corners);
    std::vector<ChartPatch> patches;
    bool ok = true;
    for (int row = 0; row < kRows && ok; ++row) {
      for (int col = 0; col < kColumns && ok; ++col) {
        const float h = static_cast<float>(0.5 * kSampledFraction);
        std::vector<cv::Point2f> in = {{col + 0.5f - h, row + 0.5f - h}, {col + 0.5f + h, row + 0.5f - h},
                                       {col + 0.5f + h, row + 0.5f + h}, {col + 0.5f - h, row + 0.5f + h},
                                       {col + 0.5f, row + 0.5f}};
        std::vector<cv::Point2f> out;
        cv::perspectiveTransform(in, out, homography);
        std::array<cv::Point2f, 4> quad = {out[0], out[1], out[2], out[3]};
        for (const auto& p : quad) ok = ok && Inside(frame_rgb, p);
        if (!ok) break;
        patches.push_back({Eigen::Vector2d(out[4].x, out[4].y), MeanOverQuad(frame_rgb, quad)});
      }
    }
    if (!ok) continue;
    std::vector<Rgb> measured;
    for (const auto& p : patches) measured.push_back(p.mean_rgb);
    const double residual =
        FitColourCorrection(measured, std::vector<Rgb>(reference.begin(), reference.end())).rms_rgb_after;
    if (residual < best_residual) best_residual = residual, best = std::move(patches);
  }
  return best;
}

double ChartPatchPitchPx(const std::vector<ChartPatch>& patches) {
  std::vector<double> steps;
  const int n = static_cast<int>(patches.size());
  for (int k = 0; k < n; ++k) {
    const int row = k / kColumns, col = k % kColumns;
    if (col + 1 < kColumns && k + 1 < n) steps.push_back((patches[k + 1].centre_px - patches[k].centre_px).norm());
    if (row + 1 < kRows && k + kColumns < n) {
      steps.push_back((patches[k + kColumns].centre_px - patches[k].centre_px).norm());
    }
  }
  if (steps.empty()) return 0.0;
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  return steps[steps.size() / 2];
}

namespace {
// M^T = argmin |X M^T - R| over the rows of x and r: r_i^T = m_i^T M^T.
Eigen::Matrix3d SolveMatrix(const Eigen::MatrixXd& x, const Eigen::MatrixXd& r) {
  return x.colPivHouseholderQr().solve(r).transpose();
}
}  // namespace

ColourFit FitColourCorrection(const std::vector<Rgb>& measured, const std::vector<Rgb>& reference) {
  ColourFit fit;
  const std::size_t n = std::min(measured.size(), reference.size());
  if (n < 3) return fit;
  Eigen::MatrixXd x(n, 3), r(n, 3);
  for (std::size_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) x(i, c) = measured[i][c], r(i, c) = reference[i][c];
  }
  fit.matrix = SolveMatrix(x, r);
  if (n > 3) {
    double sum_cv = 0;
    for (std::size_t i = 0; i < n; ++i) {
      Eigen::MatrixXd x_rest(n - 1, 3), r_rest(n - 1, 3);
      for (std::size_t j = 0, k = 0; j < n; ++j) {
        if (j == i) continue;
        x_rest.row(k) = x.row(j), r_rest.row(k) = r.row(j), ++k;
      }
      const Eigen::Vector3d corrected = SolveMatrix(x_rest, r_rest) * x.row(i).transpose();
      sum_cv += Ciede2000(LinearSrgbToLab({corrected[0], corrected[1], corrected[2]}), LinearSrgbToLab(reference[i]));
    }
    fit.delta_e_cross_validated_mean = sum_cv / n;
  }
  double sum_before = 0, sum_after = 0, sum_sq = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d m(measured[i][0], measured[i][1], measured[i][2]);
    const Eigen::Vector3d corrected = fit.matrix * m;
    const Lab reference_lab = LinearSrgbToLab(reference[i]);
    const double before = Ciede2000(LinearSrgbToLab(measured[i]), reference_lab);
    const double after = Ciede2000(LinearSrgbToLab({corrected[0], corrected[1], corrected[2]}), reference_lab);
    sum_before += before, sum_after += after;
    fit.delta_e_before_max = std::max(fit.delta_e_before_max, before);
    fit.delta_e_after_max = std::max(fit.delta_e_after_max, after);
    sum_sq += (corrected - Eigen::Vector3d(reference[i][0], reference[i][1], reference[i][2])).squaredNorm();
  }
  fit.delta_e_before_mean = sum_before / n;
  fit.delta_e_after_mean = sum_after / n;
  fit.rms_rgb_after = std::sqrt(sum_sq / (3.0 * n));
  return fit;
}

}  // namespace u3mscan

#include "bench/svg_plot.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "core/error.h"
#include "core/markup_escape.h"

namespace u3mscan::bench {

namespace {

constexpr const char* kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"};
constexpr int kColourCount = 8;
constexpr double kMarginLeft = 70, kMarginRight = 170, kMarginTop = 40, kMarginBottom = 55;

std::string Num(double v) {
  std::ostringstream s;
  s << std::setprecision(6) << v;
  return s.str();
}

// "Nice" tick values covering [lo, hi] (linear) or decades (log).
std::vector<double> Ticks(double lo, double hi, bool log_axis) {
  std::vector<double> ticks;
  if (log_axis) {
    for (double e = std::floor(lo); e <= std::ceil(hi) + 1e-9; e += 1.0) ticks.push_back(e);
    return ticks;
  }
  const double span = hi - lo;
  const double raw = span / 5.0;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  double step = magnitude;
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (raw <= m * magnitude) {
      step = m * magnitude;
      break;
    }
  }
  for (double t = std::ceil(lo / step) * step; t <= hi + 1e-9 * span; t += step) ticks.push_back(std::abs(t) < 1e-12 * step ? 0.0 : t);
  return ticks;
}

std::string TickText(double t, bool log_axis) {
  if (log_axis) return Num(std::pow(10.0, t));
  return Num(t);
}

void Marker(std::ostringstream& s, int index, double x, double y, const char* colour) {
  switch (index % 4) {
    case 0: s << "<circle cx=\"" << Num(x) << "\" cy=\"" << Num(y) << "\" r=\"4\" fill=\"" << colour << "\"/>"; break;
    case 1: s << "<rect x=\"" << Num(x - 3.5) << "\" y=\"" << Num(y - 3.5) << "\" width=\"7\" height=\"7\" fill=\"" << colour << "\"/>"; break;
    case 2:
      s << "<polygon points=\"" << Num(x) << "," << Num(y - 4.5) << " " << Num(x - 4) << "," << Num(y + 3.5) << " " << Num(x + 4)
        << "," << Num(y + 3.5) << "\" fill=\"" << colour << "\"/>";
      break;
    default:
      s << "<polygon points=\"" << Num(x) << "," << Num(y - 4.5) << " " << Num(x + 4.5) << "," << Num(y) << " " << Num(x) << ","
        << Num(y + 4.5) << " " << Num(x - 4.5) << "," << Num(y) << "\" fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"1.5\"/>";
  }
}

}  // namespace

std::string ScatterPlotSvg(const PlotSpec& spec, const std::vector<PlotSeries>& series) {
  auto tx = [&](double v) { return spec.log_x ? std::log10(v) : v; };
  auto ty = [&](double v) { return spec.log_y ? std::log10(v) : v; };
  auto usable = [&](const PlotPoint& p) {
    return std::isfinite(p.x) && std::isfinite(p.y) && (!spec.log_x || p.x > 0) && (!spec.log_y || p.y > 0);
  };
  double x_lo = INFINITY, x_hi = -INFINITY, y_lo = INFINITY, y_hi = -INFINITY;
  for (const auto& s : series) {
    for (const auto& p : s.points) {
      if (!usable(p)) continue;
      x_lo = std::min(x_lo, tx(p.x));
      x_hi = std::max(x_hi, tx(p.x));
      y_lo = std::min(y_lo, ty(p.y));
      y_hi = std::max(y_hi, ty(p.y));
    }
  }
  if (!(x_lo <= x_hi)) x_lo = 0, x_hi = 1;
  if (!(y_lo <= y_hi)) y_lo = 0, y_hi = 1;
  // Pad the ranges so markers sit inside the frame; a linear axis starts at 0 when data are positive and near it.
  auto pad = [](double* lo, double* hi, bool log_axis) {
    if (*hi - *lo < 1e-12) {
      const double d = log_axis ? 0.5 : std::max(1e-3, std::abs(*hi) * 0.1);
      *lo -= d;
      *hi += d;
    }
    const double margin = 0.06 * (*hi - *lo);
    if (!log_axis && *lo >= 0 && *lo < 0.35 * *hi) *lo = 0;
    else *lo -= margin;
    *hi += margin;
  };
  pad(&x_lo, &x_hi, spec.log_x);
  pad(&y_lo, &y_hi, spec.log_y);

  const double plot_w = spec.width_px - kMarginLeft - kMarginRight, plot_h = spec.height_px - kMarginTop - kMarginBottom;
  auto px = [&](double v) { return kMarginLeft + (tx(v) - x_lo) / (x_hi - x_lo) * plot_w; };
  auto py = [&](double v) { return kMarginTop + plot_h - (ty(v) - y_lo) / (y_hi - y_lo) * plot_h; };

  std::ostringstream s;
  s << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  s << "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"" << spec.width_px << "\" height=\"" << spec.height_px
    << "\" viewBox=\"0 0 " << spec.width_px << " " << spec.height_px << "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  s << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  s << "<text x=\"" << spec.width_px / 2 << "\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">" << EscapeMarkup(spec.title) << "</text>\n";
  s << "<rect x=\"" << kMarginLeft << "\" y=\"" << kMarginTop << "\" width=\"" << Num(plot_w) << "\" height=\"" << Num(plot_h)
    << "\" fill=\"none\" stroke=\"#444\"/>\n";
  for (double t : Ticks(x_lo, x_hi, spec.log_x)) {
    if (t < x_lo || t > x_hi) continue;
    const double x = kMarginLeft + (t - x_lo) / (x_hi - x_lo) * plot_w;
    s << "<line x1=\"" << Num(x) << "\" y1=\"" << kMarginTop << "\" x2=\"" << Num(x) << "\" y2=\"" << Num(kMarginTop + plot_h)
      << "\" stroke=\"#ddd\"/><text x=\"" << Num(x) << "\" y=\"" << Num(kMarginTop + plot_h + 16) << "\" text-anchor=\"middle\">"
      << EscapeMarkup(TickText(t, spec.log_x)) << "</text>\n";
  }
  for (double t : Ticks(y_lo, y_hi, spec.log_y)) {
    if (t < y_lo || t > y_hi) continue;
    const double y = kMarginTop + plot_h - (t - y_lo) / (y_hi - y_lo) * plot_h;
    s << "<line x1=\"" << kMarginLeft << "\" y1=\"" << Num(y) << "\" x2=\"" << Num(kMarginLeft + plot_w) << "\" y2=\"" << Num(y)
      << "\" stroke=\"#ddd\"/><text x=\"" << Num(kMarginLeft - 6) << "\" y=\"" << Num(y + 4) << "\" text-anchor=\"end\">"
      << EscapeMarkup(TickText(t, spec.log_y)) << "</text>\n";
  }
  s << "<text x=\"" << Num(kMarginLeft + plot_w / 2) << "\" y=\"" << spec.height_px - 12 << "\" text-anchor=\"middle\">"
    << EscapeMarkup(spec.x_label) << (spec.log_x ? " (log)" : "") << "</text>\n";
  s << "<text transform=\"translate(18," << Num(kMarginTop + plot_h / 2) << ") rotate(-90)\" text-anchor=\"middle\">"
    << EscapeMarkup(spec.y_label) << (spec.log_y ? " (log)" : "") << "</text>\n";

  for (std::size_t k = 0; k < series.size(); ++k) {
    const char* colour = kColours[k % kColourCount];
    std::vector<PlotPoint> points;
    for (const auto& p : series[k].points) {
      if (usable(p)) points.push_back(p);
    }
    s << "<g>\n";
    if (series[k].connect && points.size() > 1) {
      std::sort(points.begin(), points.end(), [](const PlotPoint& a, const PlotPoint& b) { return a.x < b.x; });
      s << "<polyline fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"1.2\" points=\"";
      for (const auto& p : points) s << Num(px(p.x)) << "," << Num(py(p.y)) << " ";
      s << "\"/>\n";
    }
    for (const auto& p : points) {
      s << "<g><title>" << EscapeMarkup(series[k].name + ": " + p.label + " (" + Num(p.x) + ", " + Num(p.y) + ")") << "</title>";
      Marker(s, static_cast<int>(k), px(p.x), py(p.y), colour);
      s << "</g>\n";
    }
    s << "</g>\n";
    const double ly = kMarginTop + 10 + 20.0 * static_cast<double>(k);
    const double lx = kMarginLeft + plot_w + 16;
    Marker(s, static_cast<int>(k), lx, ly, colour);
    s << "<text x=\"" << Num(lx + 10) << "\" y=\"" << Num(ly + 4) << "\">" << EscapeMarkup(series[k].name) << "</text>\n";
  }
  s << "</svg>\n";
  return s.str();
}

void WriteScatterPlotSvg(const PlotSpec& spec, const std::vector<PlotSeries>& series, const std::filesystem::path& path) {
  const std::filesystem::path temp = path.string() + ".partial";
  {
    std::ofstream out(temp, std::ios::binary);
    out << ScatterPlotSvg(spec, series);
    if (!out) throw InputError(path.string(), "", "a writable location for the plot");
  }
  std::filesystem::rename(temp, path);
}

}  // namespace u3mscan::bench

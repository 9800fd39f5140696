#pragma once
// A small SVG scatter-plot writer for the bench (no plotting dependency): axes with ticks, one
// colour and marker per series, a legend, optional log-scaled axes. Output is standalone SVG 1.1
// (well-formed XML; text is escaped).

#include <filesystem>
#include <string>
#include <vector>

namespace u3mscan::bench {

struct PlotPoint {
  double x = 0, y = 0;
  std::string label;  // shown as a tooltip (<title>)
};

struct PlotSeries {
  std::string name;
  std::vector<PlotPoint> points;
  bool connect = false;  // draw a polyline through the points in x order
};

struct PlotSpec {
  std::string title, x_label, y_label;
  bool log_x = false, log_y = false;  // non-positive values are left out on a log axis
  int width_px = 720, height_px = 480;
};

// The SVG document text.
std::string ScatterPlotSvg(const PlotSpec& spec, const std::vector<PlotSeries>& series);
// Writes it atomically (temporary file, then rename); throws InputError naming the file on failure.
void WriteScatterPlotSvg(const PlotSpec& spec, const std::vector<PlotSeries>& series, const std::filesystem::path& path);

}  // namespace u3mscan::bench

// report.html: a self-contained page an operator opens in a browser with no network. Thumbnails are
// PNGs embedded as base64 data URIs; the page has no scripts and no external references.

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "core/colour.h"
#include "core/markup_escape.h"
#include "core/text_file.h"
#include "pipeline/run_report.h"

namespace u3mscan {
namespace {

constexpr int kThumbnailSide = 256;  // longest side of a thumbnail, pixels

std::string Base64(const std::vector<unsigned char>& bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const unsigned b0 = bytes[i];
    const unsigned b1 = i + 1 < bytes.size() ? bytes[i + 1] : 0;
    const unsigned b2 = i + 2 < bytes.size() ? bytes[i + 2] : 0;
    const unsigned triple = (b0 << 16) | (b1 << 8) | b2;
    out += kAlphabet[(triple >> 18) & 63];
    out += kAlphabet[(triple >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(triple >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[triple & 63] : '=';
  }
  return out;
}

// Box-filtered, display-encoded 8-bit thumbnail (1 or 3 channels shown as grey or RGB).
// Colour images go through the sRGB curve; data maps are stretched from their min to their max
// (NaN shown black) so structure is visible whatever the units.
std::vector<unsigned char> ThumbnailPng(const ReportImage& item) {
  const Image& image = item.image;
  const int scale = std::max(1, (std::max(image.width(), image.height()) + kThumbnailSide - 1) / kThumbnailSide);
  const int w = std::max(1, image.width() / scale), h = std::max(1, image.height() / scale);
  const int channels = image.channels() >= 3 ? 3 : 1;

  float lo = 0.0f, hi = 1.0f;
  if (!item.colour) {
    lo = INFINITY;
    hi = -INFINITY;
    for (int c = 0; c < channels; ++c) {
      for (float v : image.plane(c)) {
        if (std::isfinite(v)) {
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
      }
    }
    if (!(hi > lo)) {
      hi = std::isfinite(lo) ? lo + 1.0f : 1.0f;
      if (!std::isfinite(lo)) lo = 0.0f;
    }
  }

  std::vector<unsigned char> pixels(static_cast<std::size_t>(w) * h * channels);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < channels; ++c) {
        double sum = 0.0;
        int count = 0;
        for (int dy = 0; dy < scale; ++dy) {
          for (int dx = 0; dx < scale; ++dx) {
            const float v = image.at(c, std::min(y * scale + dy, image.height() - 1), std::min(x * scale + dx, image.width() - 1));
            if (std::isfinite(v)) {
              sum += v;
              ++count;
            }
          }
        }
        double v = count ? sum / count : 0.0;
        v = item.colour ? LinearToSrgb(v) : std::clamp((v - lo) / (hi - lo), 0.0, 1.0);
        pixels[(static_cast<std::size_t>(y) * w + x) * channels + c] = static_cast<unsigned char>(std::lround(v * 255.0));
      }
    }
  }

  std::vector<unsigned char> png;
  OIIO::Filesystem::IOVecOutput proxy(png);
  auto out = OIIO::ImageOutput::create("thumbnail.png");
  if (!out) return {};
  OIIO::ImageSpec spec(w, h, channels, OIIO::TypeDesc::UINT8);
  if (!out->set_ioproxy(&proxy)) return {};
  if (!out->open("thumbnail.png", spec) || !out->write_image(OIIO::TypeDesc::UINT8, pixels.data()) || !out->close()) {
    return {};
  }
  return png;
}

std::string FormatSeconds(double seconds) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(seconds < 10 ? 2 : 1) << seconds << " s";
  return s.str();
}

void JsonTable(std::ostringstream& html, const nlohmann::json& object) {
  html << "<table><tr><th>figure</th><th>value</th></tr>\n";
  for (const auto& [key, value] : object.items()) {
    html << "<tr><td>" << EscapeMarkup(key) << "</td><td><code>" << EscapeMarkup(value.dump()) << "</code></td></tr>\n";
  }
  html << "</table>\n";
}

}  // namespace

void WriteReportHtml(const RunReport& report, const std::filesystem::path& path) {
  std::ostringstream html;
  html << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>u3mscan report: "
       << EscapeMarkup(report.capture_name) << "</title>\n<style>\n"
       << "body{font-family:sans-serif;margin:2em;max-width:1200px;color:#222}"
       << "table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #bbb;padding:3px 8px;text-align:left}"
       << "th{background:#eee}.skipped{color:#777}.failed{color:#b00}figure{display:inline-block;margin:6px;text-align:center}"
       << "figure img{border:1px solid #999;image-rendering:pixelated;max-width:256px}figcaption{font-size:85%}\n"
       << "</style></head><body>\n";
  html << "<h1>" << EscapeMarkup(report.capture_name) << "</h1>\n<p>Capture <code>" << EscapeMarkup(report.capture_path)
       << "</code> &rarr; <code>" << EscapeMarkup(report.output_path) << "</code><br>Status: <b"
       << (report.status == "ok" ? "" : " class=\"failed\"") << ">" << EscapeMarkup(report.status) << "</b>";
  if (!report.error.empty()) html << " &mdash; " << EscapeMarkup(report.error);
  html << "<br>Started " << EscapeMarkup(report.started_utc) << ", preset <b>" << EscapeMarkup(report.preset)
       << "</b>, total " << FormatSeconds(report.total_seconds) << ", peak memory " << std::fixed
       << std::setprecision(0) << report.peak_memory_mib << " MiB</p>\n";

  html << "<h2>Steps</h2>\n<table><tr><th>step</th><th>ran</th><th>time</th><th>why</th></tr>\n";
  for (const auto& step : report.steps) {
    html << "<tr" << (step.ran ? "" : " class=\"skipped\"") << "><td>" << EscapeMarkup(step.name) << "</td><td>"
         << (step.ran ? "yes" : "skipped") << "</td><td>" << (step.ran ? FormatSeconds(step.seconds) : "")
         << "</td><td>" << EscapeMarkup(step.reason) << "</td></tr>\n";
  }
  html << "</table>\n";

  html << "<h2>Parameters</h2>\n<table><tr><th>parameter</th><th>value</th><th>source</th><th>why</th></tr>\n";
  for (const auto& p : report.parameters) {
    html << "<tr" << (p.source == ParameterSource::kDefault ? " class=\"skipped\"" : "") << "><td>"
         << EscapeMarkup(p.name) << "</td><td>" << std::setprecision(4) << std::defaultfloat << p.value;
    if (p.uncertainty > 0) html << " &plusmn; " << p.uncertainty;
    html << "</td><td>" << ParameterSourceName(p.source) << (p.reliable() ? "" : ", UNRELIABLE") << "</td><td>"
         << EscapeMarkup(p.reason) << (p.reliable() ? "" : "; unreliable: " + EscapeMarkup(p.unreliable_reason))
         << "</td></tr>\n";
  }
  html << "</table>\n";

  if (!report.calibration.empty()) {
    html << "<h2>Calibration</h2>\n";
    JsonTable(html, report.calibration);
  }
  if (!report.quality.empty()) {
    html << "<h2>Quality</h2>\n";
    JsonTable(html, report.quality);
  }
  if (!report.warnings.empty()) {
    html << "<h2>Warnings</h2>\n<ul>\n";
    for (const auto& w : report.warnings) html << "<li>" << EscapeMarkup(w) << "</li>\n";
    html << "</ul>\n";
  }

  for (const char* group : {"input", "map", "quality"}) {
    bool header = false;
    for (const auto& item : report.images) {
      if (item.group != group || item.image.empty()) continue;
      if (!header) {
        html << "<h2>" << (std::string(group) == "input" ? "Input frames" : std::string(group) == "map" ? "Maps" : "Confidence and residuals")
             << "</h2>\n<div>\n";
        header = true;
      }
      const auto png = ThumbnailPng(item);
      html << "<figure><img alt=\"" << EscapeMarkup(item.label) << "\" src=\"data:image/png;base64," << Base64(png)
           << "\"><figcaption>" << EscapeMarkup(item.label) << "</figcaption></figure>\n";
    }
    if (header) html << "</div>\n";
  }
  html << "</body></html>\n";

  WriteTextFileAtomically(path, html.str(), "a writable location for the report");
}

}  // namespace u3mscan

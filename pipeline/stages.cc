#include "pipeline/stages.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/error.h"
#include "core/logging.h"

namespace u3mscan {

double StageClock() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

PreparedCapture PrepareCapture(const std::filesystem::path& capture_dir, StageOptions& options, RunReport* report,
                               const ProgressCallback& progress) {
  double start = StageClock();
  Capture capture = Capture::Open(capture_dir);
  report->steps.push_back({"read manifest", true, std::to_string(capture.frame_count()) + " frames listed", StageClock() - start});

  std::vector<std::string> sides;
  for (const char* side : {"front", "back"}) {
    FrameFilter filter;
    filter.role = FrameRole::kSample;
    filter.side = side;
    if (!capture.Frames(filter).empty()) sides.push_back(side);
  }
  if (sides.empty()) {
    throw InputError((capture.folder() / "capture.json").string(), "/frames", "at least one frame with role \"sample\"");
  }
  if (sides.size() == 1 && sides[0] == "front") {
    report->steps.push_back({"back side", false, "the capture has no back-side sample frames: back = front", 0.0});
  }

  start = StageClock();
  CalibrationResult calibration = Calibrate(capture, options.calibration, progress);
  const double calibrate_s = StageClock() - start;
  for (const StepReport& step : calibration.steps) {
    report->steps.push_back({"calibration: " + step.step, step.ran, step.detail, 0.0});
  }
  report->steps.push_back({"calibration (total)", true, "", calibrate_s});
  for (const std::string& warning : calibration.warnings) report->warnings.push_back(warning);
  report->calibration = calibration.ToJson();
  return PreparedCapture{std::move(capture), std::move(calibration), std::move(sides)};
}

Stack BuildSideStack(const PreparedCapture& prepared, const std::string& side, const StageOptions& options,
                     RunReport* report, const ProgressCallback& progress) {
  const double start = StageClock();
  CalibrationOptions calibration_options = options.calibration;
  calibration_options.side = side;
  Stack stack = BuildStack(prepared.capture, prepared.calibration, calibration_options, progress);
  report->steps.push_back({"rectify " + side, true,
                           std::to_string(stack.observations.size()) + " observations on a " +
                               std::to_string(stack.grid.width) + "x" + std::to_string(stack.grid.height) + " grid",
                           StageClock() - start});
  return stack;
}

SideReconstruction ReconstructSide(const Stack& stack, const StageOptions& options, const Image& alpha,
                                   RunReport* report, const ProgressCallback& progress) {
  SideReconstruction out;
  const bool near = std::any_of(stack.lights.begin(), stack.lights.end(),
                                [](const LightModel& l) { return l.type == LightType::kPoint; });
  double start = StageClock();
  out.photometric_stereo = reconstruction::RunPhotometricStereo(stack, options.photometric_stereo, progress);
  const auto& ps = out.photometric_stereo;
  report->steps.push_back({"photometric stereo (" + reconstruction::PsSolverName(options.photometric_stereo.solver) + ")",
                           true,
                           near ? "near point lights, height refined " + std::to_string(ps.near_iterations) + " rounds"
                                : "distant lights",
                           StageClock() - start});

  // Valid surface: seen by the camera and not a hole (alpha >= 0.5).
  out.valid = Image(stack.grid.width, stack.grid.height, 1, 1.0f, stack.grid.pitch_mm);
  if (!alpha.empty()) {
    auto v = out.valid.plane(0);
    const auto a = alpha.plane(0);
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = a[i] >= 0.5f ? 1.0f : 0.0f;
  }

  start = StageClock();
  if (near && !ps.height_mm.empty() && alpha.empty()) {
    out.height_mm = ps.height_mm;
    report->steps.push_back({"integration", false, "done inside the near-light refinement", 0.0});
  } else {
    reconstruction::IntegrationOptions integration = near ? options.photometric_stereo.integration : options.integration;
    integration.pitch_mm = stack.grid.pitch_mm;
    out.height_mm = reconstruction::IntegrateNormals(ps.normal, out.valid, integration, progress).height_mm;
    report->steps.push_back({"integration (" + reconstruction::IntegratorName(integration.method) + ")", true,
                             alpha.empty() ? "whole grid" : "holes masked out", StageClock() - start});
  }
  out.height_mm.set_pitch_mm(stack.grid.pitch_mm);
  return out;
}

fitting::FitResult FitSide(const Stack& stack, const SideReconstruction& geometry, const StageOptions& options,
                           RunReport* report, const ProgressCallback& progress) {
  const double start = StageClock();
  fitting::SurfaceGeometry surface{geometry.photometric_stereo.normal, geometry.photometric_stereo.albedo,
                                   geometry.height_mm};
  fitting::FitResult fit = fitting::FitPrincipled(stack, surface, options.fit, progress);
  std::string detail = std::to_string(fit.clusters.size()) + " clusters";
  if (!fit.convergence.all_converged) {
    detail += ", " + std::to_string(fit.convergence.clusters_failed) + " did not converge";
    for (const auto& message : fit.convergence.messages) report->warnings.push_back("fit: " + message);
  }
  report->steps.push_back({"fit", true, detail, StageClock() - start});
  return fit;
}

Image FitResidualMap(const fitting::FitResult& fit, const Stack& stack, const SideReconstruction& geometry,
                     int max_observations, double* mean_out) {
  const int w = stack.grid.width, h = stack.grid.height;
  Image residual(w, h, 1, 0.0f, stack.grid.pitch_mm);
  std::vector<float> count(static_cast<std::size_t>(w) * h, 0.0f);
  const fitting::SurfaceGeometry surface{geometry.photometric_stereo.normal, geometry.photometric_stereo.albedo,
                                         geometry.height_mm};
  const int n = static_cast<int>(stack.observations.size());
  const int used = std::min(n, std::max(1, max_observations));
  for (int k = 0; k < used; ++k) {
    const Observation& observation = stack.observations[static_cast<std::size_t>(k) * n / used];
    const Image render = fitting::RenderFitted(fit, stack, surface, observation);
    for (std::size_t i = 0; i < count.size(); ++i) {
      if (!observation.flags.empty() && observation.flags[i] != 0) continue;
      double data = 0.0, diff = 0.0;
      for (int c = 0; c < 3; ++c) {
        data += observation.rgb.plane(c)[i];
        diff += std::abs(render.plane(c)[i] - observation.rgb.plane(c)[i]);
      }
      if (!(data > 0.0) || !std::isfinite(diff)) continue;
      residual.plane(0)[i] += static_cast<float>(diff / data);
      count[i] += 1.0f;
    }
  }
  double sum = 0.0;
  std::size_t pixels = 0;
  for (std::size_t i = 0; i < count.size(); ++i) {
    if (count[i] > 0.0f) {
      residual.plane(0)[i] /= count[i];
      sum += residual.plane(0)[i];
      ++pixels;
    }
  }
  if (mean_out) *mean_out = pixels ? sum / static_cast<double>(pixels) : 0.0;
  return residual;
}

}  // namespace u3mscan

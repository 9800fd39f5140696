#include "pipeline/tiled_side.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <optional>
#include <string>

#include "capture/stack_builder.h"
#include "pipeline/band_shadow_marks.h"
#include "core/elapsed.h"
#include "core/logging.h"
#include "fitting/tiled_fit.h"
#include "pipeline/fine_colour.h"
#include "pipeline/fine_grid.h"
#include "pipeline/relief_registration.h"
#include "pipeline/supersampled_reconstruction.h"
#include "pipeline/top_view_normals.h"
#include "reconstruction/cast_shadows.h"
#include "reconstruction/normal_integration.h"
#include "reconstruction/photometric_stereo.h"

namespace u3mscan {
namespace {

using reconstruction::PhotometricStereoResult;

// The band Stacks of one side, built again on every sweep; times the building. On the maps' grid,
// or (`fine_factor` k > 1) on the fine grid of --ps-supersample: band b is then the fine rows of the
// maps' band b (k times as many).
class Bands {
 public:
  Bands(const Capture& capture, const CalibrationResult& calibration, const std::string& side, const StageOptions& options,
        const TilePlan& plan, int fine_factor = 1)
      : capture_(capture), calibration_(calibration), bands_(plan.bands), band_rows_(plan.band_rows * fine_factor) {
    options_ = options.calibration;
    options_.side = side;
  }
  int count() const { return bands_; }
  int Row0(int band) const { return band * band_rows_; }
  int Rows(int band) const { return std::min(band_rows_, calibration_.grid.height - Row0(band)); }
  const MetricGrid& grid() const { return calibration_.grid; }
  // From here on every band is built at these heights (the whole grid's, mm, world z) and its
  // pixels hidden from a tilted view are marked (relief_registration.h).
  void PutOnRelief(Image surface_z_mm) { relief_ = std::move(surface_z_mm); }
  Stack Build(const std::vector<std::size_t>& frames, int band) {
    const double start = SteadySeconds();
    Stack stack = BuildStackRows(capture_, calibration_, options_, frames, Row0(band), Rows(band), {}, relief_);
    if (!relief_.empty()) {
      const double pixels = static_cast<double>(stack.grid.width) * stack.grid.height;
      hidden_sum_ += MarkHiddenFromTiltedViews(relief_, calibration_.grid, &stack) * pixels;
      hidden_pixels_ += pixels;
    }
    build_seconds_ += SteadySeconds() - start;
    ++builds_;
    return stack;
  }
  double build_seconds() const { return build_seconds_; }
  int builds() const { return builds_; }
  // Share of the tilted views' pixels marked hidden over the bands built on the relief so far.
  double hidden_share() const { return hidden_pixels_ > 0.0 ? hidden_sum_ / hidden_pixels_ : 0.0; }

 private:
  const Capture& capture_;
  const CalibrationResult& calibration_;
  int bands_ = 1, band_rows_ = 0;
  CalibrationOptions options_;
  Image relief_;
  double build_seconds_ = 0.0;
  int builds_ = 0;
  double hidden_sum_ = 0.0, hidden_pixels_ = 0.0;
};

// Appends a band's sampled pixels to the sample Stack (allocated on the first band).
void AddToSample(const Stack& band, int row0, int step, const MetricGrid& sample_grid, Stack* sample) {
  if (sample->observations.empty()) {
    sample->side = band.side;
    sample->grid = sample_grid;
    sample->lights = band.lights;
    sample->views = band.views;
    sample->observations.resize(band.observations.size());
    for (std::size_t k = 0; k < band.observations.size(); ++k) {
      sample->observations[k].view = band.observations[k].view;
      sample->observations[k].light = band.observations[k].light;
    }
  }
  const int o = step / 2;
  for (std::size_t k = 0; k < band.observations.size(); ++k) {
    const Observation& from = band.observations[k];
    Observation& to = sample->observations[k];
    SampleRows(from.rgb, row0, step, sample_grid, &to.rgb);
    if (!from.irradiance.empty()) SampleRows(from.irradiance, row0, step, sample_grid, &to.irradiance);
    if (from.flags.empty()) continue;
    if (to.flags.empty()) to.flags.assign(static_cast<std::size_t>(sample_grid.width) * sample_grid.height, 0);
    for (int r = 0; r < band.grid.height; ++r) {
      const int row = row0 + r;
      if (row < o || (row - o) % step != 0 || (row - o) / step >= sample_grid.height) continue;
      const int i = (row - o) / step;
      for (int j = 0; j < sample_grid.width; ++j) {
        to.flags[static_cast<std::size_t>(i) * sample_grid.width + j] =
            from.flags[static_cast<std::size_t>(r) * band.grid.width + o + j * step];
      }
    }
  }
}

// Full-size photometric stereo maps, filled band by band.
PhotometricStereoResult EmptyPs(const MetricGrid& grid) {
  PhotometricStereoResult ps;
  ps.normal = Image(grid.width, grid.height, 3, 0.0f, grid.pitch_mm);
  ps.albedo = Image(grid.width, grid.height, 3, 0.0f, grid.pitch_mm);
  ps.confidence = Image(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
  ps.condition_number = Image(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
  ps.used_lights = Image(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
  ps.pixel_states.assign(static_cast<std::size_t>(grid.width) * grid.height, 0);
  return ps;
}

void PasteBand(const PhotometricStereoResult& band, int row0, PhotometricStereoResult* full) {
  PasteRows(band.normal, row0, &full->normal);
  PasteRows(band.albedo, row0, &full->albedo);
  PasteRows(band.confidence, row0, &full->confidence);
  PasteRows(band.condition_number, row0, &full->condition_number);
  PasteRows(band.used_lights, row0, &full->used_lights);
  // A solve's own states (not an average onto the maps, which has none): what solving it again needs.
  if (!band.pixel_states.empty()) {
    std::copy(band.pixel_states.begin(), band.pixel_states.end(),
              full->pixel_states.begin() + static_cast<std::ptrdiff_t>(row0) * full->normal.width());
  }
  full->ill_conditioned_pixels += band.ill_conditioned_pixels;
  full->dark_pixels += band.dark_pixels;
  full->low_albedo_pixels += band.low_albedo_pixels;
  full->clamped_normal_pixels += band.clamped_normal_pixels;
  full->regularised_pixels += band.regularised_pixels;
}

// Rows [row0, row0 + rows) of a whole solve: its maps and pixel states (the counts are not split).
PhotometricStereoResult CropPs(const PhotometricStereoResult& whole, int row0, int rows) {
  PhotometricStereoResult band;
  band.normal = CropRows(whole.normal, row0, rows);
  band.albedo = CropRows(whole.albedo, row0, rows);
  band.confidence = CropRows(whole.confidence, row0, rows);
  band.condition_number = CropRows(whole.condition_number, row0, rows);
  band.used_lights = CropRows(whole.used_lights, row0, rows);
  const auto first = whole.pixel_states.begin() + static_cast<std::ptrdiff_t>(row0) * whole.normal.width();
  band.pixel_states.assign(first, first + static_cast<std::ptrdiff_t>(rows) * whole.normal.width());
  return band;
}

// Mean angle between two normal maps, degrees (as RunPhotometricStereo's refinement measures it).
fitting::FitResult BandFit(const fitting::FitResult& fit, int row0, int rows) {
  fitting::FitResult band;
  band.base_color = CropRows(fit.base_color, row0, rows);
  band.cluster_id = CropRows(fit.cluster_id, row0, rows);
  for (int i = 0; i < fitting::kFitParameterCount; ++i) {
    if (!fit.parameter_maps[i].empty()) band.parameter_maps[i] = CropRows(fit.parameter_maps[i], row0, rows);
  }
  if (!fit.anisotropy_rotation_deg.empty()) band.anisotropy_rotation_deg = CropRows(fit.anisotropy_rotation_deg, row0, rows);
  band.maps = fit.maps;
  band.rotation_report = fit.rotation_report;
  band.clusters = fit.clusters;
  band.options = fit.options;
  return band;
}

// A band's rows [row0, row0 + rows) of the side's reconstruction: normals, albedo and heights, and
// with `facets` (may be empty: the whole side's normals `fine_factor` times finer, which the fit
// takes as each map pixel's facets, SideReconstruction::fine_normals) the band's k rows a map row.
SideReconstruction BandSide(const SideReconstruction& geometry, int row0, int rows, const Image& facets = Image(),
                            int fine_factor = 1) {
  SideReconstruction band;
  band.photometric_stereo.normal = CropRows(geometry.photometric_stereo.normal, row0, rows);
  band.photometric_stereo.albedo = CropRows(geometry.photometric_stereo.albedo, row0, rows);
  band.height_mm = CropRows(geometry.height_mm, row0, rows);
  if (!facets.empty()) {
    band.fine_normals = CropRows(facets, row0 * fine_factor, rows * fine_factor);
    band.fine_factor = fine_factor;
  }
  return band;
}

// The surface the fit and the held-out check see on a band (BandSide), with the rows of the
// fibres' turns when there are any (`turns`, on the whole grid).
fitting::SurfaceGeometry BandSurface(const SideReconstruction& geometry, int row0, int rows, const Image& turns = Image(),
                                     const Image& facets = Image(), int fine_factor = 1) {
  fitting::SurfaceGeometry surface = SideSurface(BandSide(geometry, row0, rows, facets, fine_factor));
  if (!turns.empty()) surface.fibre_turn_deg = CropRows(turns, row0, rows);
  return surface;
}

}  // namespace

TiledSide ProcessSideTiled(const PreparedCapture& prepared, const std::string& side, const StageOptions& options,
                           const TilePlan& plan, const Image& alpha, int residual_observations,
                           const std::vector<std::string>& hold_out_lights, RunReport* report,
                           const ProgressCallback& progress) {
  TiledSide out;
  const MetricGrid& grid = prepared.calibration.grid;
  // A copy: the diffuse roughness, once chosen on the sample, is fixed for every band.
  reconstruction::PhotometricStereoOptions ps_options = options.photometric_stereo;
  Bands bands(prepared.capture, prepared.calibration, side, options, plan);
  // --ps-supersample (plan.fine_factor k > 1): photometric stereo, and the fit's normal refinement,
  // on bands of the grid k times finer (pipeline/fine_grid.h); every other sweep on the maps' grid.
  const int fine_factor = plan.fine_factor;
  const CalibrationResult fine_calibration =
      fine_factor > 1 ? FineCalibration(prepared.calibration, fine_factor) : CalibrationResult();
  Bands fine_bands(prepared.capture, fine_calibration, side, options, plan, fine_factor);
  std::vector<std::size_t> frames = SideSampleFrames(prepared.capture.manifest(), side);
  // Held-out lights: their frames take no part in any sweep until the check at the end.
  const std::vector<std::size_t> held_out_frames =
      hold_out_lights.empty() ? std::vector<std::size_t>{}
                              : TakeHeldOutFrames(prepared.capture.manifest(), side, hold_out_lights, &frames);
  const int step = plan.sample_step;
  const MetricGrid sample_grid = SampleGrid(grid, step);
  LogInfo() << "process (" << side << "): " << plan.bands << " bands of " << plan.band_rows << " rows ("
            << plan.whole_stack_bytes / (1 << 30) << " GiB for the whole stack), fit sample every " << step
            << " pixels (" << sample_grid.width << " x " << sample_grid.height << ")";
  double solve_seconds = 0.0;

  // Cast shadows (reconstruction/cast_shadows.h): a band is marked with the whole map's heights
  // (its rows offset), so that shadows cast from outside the band are found as in a one-band run.
  double shadow_seconds = 0.0;
  reconstruction::CastShadowCounts shadow_counts;  // of the last photometric stereo sweep
  auto mark = [&](const Image& height, const MetricGrid& height_grid, Stack* stack) {
    const double start = SteadySeconds();
    const reconstruction::CastShadowCounts counts =
        reconstruction::MarkCastShadows(height, height_grid, stack, options.cast_shadows);
    shadow_seconds += SteadySeconds() - start;
    return counts;
  };

  // With a fine factor and distant lights, the fine bands' cast shadows are marked from heights
  // integrated on the whole fine grid (as one band marks its fine stack: RunPhotometricStereoMarkingShadows
  // there), not from the maps' heights taken there bilinearly, which are too smooth to place the
  // shadows of a yarn's wall (plain at 3x in 3 bands: normals 1.27 -> 1.13 deg, base colour dE
  // 0.92 -> 0.49; one band 1.14 and 0.50; docs/process.md). The first sweep keeps the fine unit
  // normals and confidence for it: in fine_first (below) with distant lights, else in
  // fine_last_normal and fine_last_confidence (16 B a fine pixel, released once integrated). Near
  // lights refined on the finer grid keep the latter every round (below, "Near point lights").
  Image fine_shadow_height;
  Image fine_last_normal, fine_last_confidence;
  // With keep_last_albedo (set below, before the first sweep) those sweeps' fine albedo too.
  Image fine_last_albedo;
  bool keep_last_albedo = false;
  // With distant lights, the first sweep's whole fine solve (37 B a fine pixel: maps and pixel
  // states), from which the marked sweep solves again only the pixels a mark changes
  // (SolvePhotometricStereoAgain, as one band does); that sweep updates it in place, and the fit
  // takes its normals and albedo. Without a fine factor the first sweep's full maps serve.
  PhotometricStereoResult fine_first;
  double solved_again_share = -1.0;  // of the solve grid's pixels, in the marked sweep (-1: none ran)

  // One sweep of photometric stereo at the given heights (nullptr: the anchor plane), the bands'
  // cast shadows marked from the whole-map heights `marks_from` (nullptr: none). With a fine factor
  // the bands are the fine grid's, the heights taken there bilinearly (the marks from
  // fine_shadow_height instead when it is set and `marks_from` is shadow_height), and each band's
  // result averaged onto the maps' rows (AveragePhotometricStereoOntoMaps); `sample` must then be
  // null (the sample is on the maps' grid: a sweep of its own gathers it). `role.fine_heights` (on the
  // fine grid; nullptr: none) replaces `height` there, and `marks_from` too when that is `height`.
  // `role` says what the sweep keeps or reuses besides its maps (SweepRole).
  // The fit's clusters on a sample of the finer grid (below, before the fit): one fine pixel in each
  // block of step x step map pixels, with its fine normal and albedo, taken from the marked, solved
  // fine bands. The sweep whose fine solves the fit would repeat gathers it (`role.gather_fine_sample`),
  // so that no sweep runs for it alone (distant lights; near lights refined in rounds do not know
  // their last sweep in advance, and the fit gathers theirs in a sweep of its own).
  const bool fine_fit = fine_factor > 1 && options.fit.refine_pixel_normals;
  const int fine_step = step * fine_factor;
  const MetricGrid fine_sample_grid = fine_factor > 1 ? SampleGrid(fine_calibration.grid, fine_step) : MetricGrid();
  Stack fine_sample;
  fitting::SurfaceGeometry fine_sample_geometry;  // its normals and albedo (the heights once integrated)
  bool fine_sample_gathered = false;
  // With --follow-fibres: each fine band's fibre turns (from its normals) go into that sample and,
  // averaged onto the maps (fibre_direction.h), into the maps' grid's turns, as one band takes them.
  Image fine_turns_on_maps;
  auto add_fine_turns = [&](const Image& band_turns, int row0) {
    if (band_turns.empty()) return;
    SampleRows(band_turns, row0, fine_step, fine_sample_grid, &fine_sample_geometry.fibre_turn_deg);
    if (fine_turns_on_maps.empty()) fine_turns_on_maps = Image(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
    PasteRows(AverageTurnsOntoMaps(band_turns, fine_factor, grid.pitch_mm), row0 / fine_factor, &fine_turns_on_maps);
  };
  // The last sweep's fine normals and albedo, kept whole for the fit's fine pass (24 B a fine pixel)
  // so that it does not solve every fine band once more (the 36 MP plain's fine pass of the fit
  // 588 -> 395 s, docs/process.md). Kept when the last sweep is known before it runs
  // (distant lights, or near ones not refined); near-light rounds, which may end on a rejected
  // round, leave them empty and the fit solves the fine bands again at the kept round's heights.
  bool keep_last_fine_solve = false;  // set below, once the sample tells the lights
  Image fine_fit_normal, fine_fit_albedo;
  // With them, that sweep's cast-shadow marks on the fine bands (1 bit a fine pixel and light): the
  // fit's fine pass marks from the same heights, so it takes them instead of marching again.
  BandShadowMarks fine_band_marks;
  Image shadow_height;  // the whole-map heights the final marks come from (empty: marking off)
  // What one sweep keeps or reuses besides its maps.
  struct SweepRole {
    bool keep_fine = false;                // the fine bands' normals and confidence into fine_last_*
    const Image* fine_heights = nullptr;   // the solve's heights on the fine grid (see above)
    bool gather_fine_sample = false;       // the fit's sample of the finer grid, from this sweep's solves
    bool last_sweep = false;               // the fit's fine pass takes this sweep's fine solves and marks (keep_last_fine_solve)
    bool keep_whole = false;               // the whole solve kept to be solved again (fine_first, or the maps)
    const PhotometricStereoResult* earlier = nullptr;  // solve again from it: only pixels with a new mark
  };
  auto solve_sweep = [&](const Image* height, const Image* marks_from, Stack* sample, const char* stage,
                         const SweepRole& role = {}) {
    if (role.gather_fine_sample && fine_factor > 1) {
      fine_sample = Stack();
      fine_sample_geometry = fitting::SurfaceGeometry();
      fine_sample_gathered = true;
    }
    const bool keep_for_fit = role.last_sweep && keep_last_fine_solve && fine_factor > 1;
    PhotometricStereoResult full = EmptyPs(grid);
    shadow_counts = {};
    Bands& solved = fine_factor > 1 ? fine_bands : bands;
    const MetricGrid& solve_grid = solved.grid();
    Image fine_height, fine_marks;
    if (fine_factor > 1 && height && !role.fine_heights) fine_height = UpsampleLinear(*height, fine_factor);
    const Image* solve_height = fine_factor > 1 ? (height ? (role.fine_heights ? role.fine_heights : &fine_height) : nullptr) : height;
    const Image* marks = marks_from;
    if (fine_factor > 1 && marks_from) {
      if (marks_from == height && role.fine_heights) {
        marks = role.fine_heights;
      } else if (marks_from == &shadow_height && !fine_shadow_height.empty()) {
        marks = &fine_shadow_height;
      } else if (marks_from == height) {
        marks = &fine_height;
      } else {
        fine_marks = UpsampleLinear(*marks_from, fine_factor);
        marks = &fine_marks;
      }
    }
    if (role.keep_fine && fine_factor > 1 && fine_last_normal.empty()) {
      fine_last_normal = Image(solve_grid.width, solve_grid.height, 3, 0.0f, solve_grid.pitch_mm);
      fine_last_confidence = Image(solve_grid.width, solve_grid.height, 1, 0.0f, solve_grid.pitch_mm);
      if (keep_last_albedo) fine_last_albedo = Image(solve_grid.width, solve_grid.height, 3, 0.0f, solve_grid.pitch_mm);
    }
    // Solving again from fine_first updates it in place (a band's rows are cropped before its solve);
    // the fit then takes its normals and albedo.
    const bool again_in_place = fine_factor > 1 && role.earlier == &fine_first;
    if (keep_for_fit && !again_in_place) {
      fine_fit_normal = Image(solve_grid.width, solve_grid.height, 3, 0.0f, solve_grid.pitch_mm);
      fine_fit_albedo = Image(solve_grid.width, solve_grid.height, 3, 0.0f, solve_grid.pitch_mm);
    }
    if (role.keep_whole && fine_factor > 1) fine_first = EmptyPs(solve_grid);
    long long kept_pixels = 0;
    for (int b = 0; b < solved.count(); ++b) {
      Stack band = solved.Build(frames, b);
      if (sample) AddToSample(band, bands.Row0(b), step, sample_grid, sample);
      if (marks) {
        const reconstruction::CastShadowCounts counts = mark(*marks, solve_grid, &band);
        shadow_counts.marked += counts.marked;
        shadow_counts.examined += counts.examined;
        if (keep_for_fit) {
          if (fine_band_marks.empty()) {
            fine_band_marks = BandShadowMarks(solve_grid.width, solve_grid.height, static_cast<int>(band.lights.size()));
          }
          fine_band_marks.Keep(band, solved.Row0(b));
        }
      }
      const double start = SteadySeconds();
      const Image band_height =
          solve_height ? CropRows(*solve_height, solved.Row0(b), solved.Rows(b))
                       : Image(solve_grid.width, solved.Rows(b), 1, static_cast<float>(ps_options.integration.mean_height_mm),
                               solve_grid.pitch_mm);
      PhotometricStereoResult band_ps =
          role.earlier ? reconstruction::SolvePhotometricStereoAgain(band, ps_options, band_height,
                                                                     CropPs(*role.earlier, solved.Row0(b), solved.Rows(b)),
                                                                     kCastShadow)
                       : reconstruction::SolvePhotometricStereoAt(band, ps_options, band_height);
      kept_pixels += band_ps.kept_pixels;
      if ((role.keep_whole || again_in_place) && fine_factor > 1) PasteBand(band_ps, solved.Row0(b), &fine_first);
      if (role.gather_fine_sample && fine_factor > 1) {
        AddToSample(band, solved.Row0(b), fine_step, fine_sample_grid, &fine_sample);
        SampleRows(band_ps.normal, solved.Row0(b), fine_step, fine_sample_grid, &fine_sample_geometry.normals);
        SampleRows(band_ps.albedo, solved.Row0(b), fine_step, fine_sample_grid, &fine_sample_geometry.albedo);
        add_fine_turns(FibreTurnsIfFollowed(band_ps.normal, options), solved.Row0(b));
      }
      if (role.keep_fine && fine_factor > 1) {
        PasteRows(band_ps.normal, solved.Row0(b), &fine_last_normal);
        PasteRows(band_ps.confidence, solved.Row0(b), &fine_last_confidence);
        if (!fine_last_albedo.empty()) PasteRows(band_ps.albedo, solved.Row0(b), &fine_last_albedo);
      }
      if (keep_for_fit && !again_in_place) {
        PasteRows(band_ps.normal, solved.Row0(b), &fine_fit_normal);
        PasteRows(band_ps.albedo, solved.Row0(b), &fine_fit_albedo);
      }
      if (fine_factor > 1) {
        // Not placed on the plan (one band's is): a placed square reaches the next band's rows,
        // which this band does not hold; the fit's refined normals, written, are placed.
        band_ps = AveragePhotometricStereoOntoMaps(band_ps, fine_factor, grid.pitch_mm, options.integration.parallax,
                                                   solved.Row0(b));
      }
      PasteBand(band_ps, bands.Row0(b), &full);
      solve_seconds += SteadySeconds() - start;
      ReportProgress(progress, stage, static_cast<double>(b + 1) / bands.count());
    }
    if (marks) {  // every pixel solved again, but those an earlier solve kept
      solved_again_share = 1.0 - static_cast<double>(kept_pixels) / (static_cast<double>(solve_grid.width) * solve_grid.height);
    }
    if (again_in_place) {
      if (keep_for_fit) {
        fine_fit_normal = std::move(fine_first.normal);
        fine_fit_albedo = std::move(fine_first.albedo);
      }
      fine_first = PhotometricStereoResult();
    }
    return full;
  };

  // The fit's sample alone, one sweep of the maps' bands (built at the relief once PutOnRelief).
  auto sample_sweep = [&](const char* stage) {
    Stack sample;
    for (int b = 0; b < bands.count(); ++b) {
      AddToSample(bands.Build(frames, b), bands.Row0(b), step, sample_grid, &sample);
      ReportProgress(progress, stage, static_cast<double>(b + 1) / bands.count());
    }
    return sample;
  };

  // The Burley diffuse roughness is one value for the whole side (RunPhotometricStereo estimates it
  // on the whole stack): when it is to be estimated, the first sweep only gathers the sample, the
  // roughness is chosen on it, and every band is then solved with that value. Estimating it per
  // band would give each band its own lobe (and a band solved without it, Lambert's law).
  const bool choose_roughness = ps_options.diffuse_model == reconstruction::DiffuseModel::kBurley &&
                                ps_options.diffuse_roughness < 0.0;
  auto keep_checked_frames = [&] {
    const std::vector<std::size_t> kept = CheckSideStack(prepared, side, options, &out.sample, report);
    if (kept.size() == frames.size()) return false;
    std::vector<std::size_t> kept_frames;
    for (std::size_t k : kept) kept_frames.push_back(frames[k]);
    frames = std::move(kept_frames);
    return true;
  };
  PhotometricStereoResult ps;
  if (choose_roughness || fine_factor > 1) {
    out.sample = sample_sweep("photometric stereo (sample)");
    keep_checked_frames();
  }
  // A tilted view with a finer grid: the fit takes the fine solves' normals as the facets each
  // camera sees in a map pixel, as one band does (ReconstructSideSupersampled; docs/fitting.md,
  // "Facets of the finer grid"): the whole fine grid's, 12 B a fine pixel.
  const bool fit_facets = fine_factor > 1 && options.fit_facets && NeedsReliefRegistration(out.sample);
  Image facet_normals;
  // A tilted view: the normals refined on the fine bands against its top view alone, once the
  // clusters are fitted (top_view_normals.h); the bands' other views are left out of that pass.
  const bool top_view_fit = RefinesTopViewNormals(options, fine_factor);
  // The facets' solve and that pass read the top view alone: their fine bands are built from its
  // frames only, not from every view's.
  const std::string top_camera = fit_facets || top_view_fit
                                     ? out.sample.views.at(static_cast<std::size_t>(MostVerticalView(out.sample))).camera_id
                                     : std::string();
  // With the facets from the near-light rounds (below), their sweep's fine albedo beside them (12 B
  // a fine pixel), so that the top view's pass takes both instead of solving every fine band again.
  Image facet_albedo;
  // Fine bands of distant lights whose shadows are marked: the first solve's fine normals kept
  // for the fine heights (fine_shadow_height above). Near lights refined on fine bands: every
  // sweep's, for the next round's heights. The sample, and so the lights, are known.
  const bool fine_near_rounds = fine_factor > 1 && HasPointLights(out.sample) && ps_options.refine_height;
  keep_last_albedo = top_view_fit && fit_facets && fine_near_rounds;
  // Distant lights marked after the first sweep: the marked sweep solves again only the pixels a
  // mark changes, from the first sweep's whole solve (SolvePhotometricStereoAgain, as one band).
  const bool solve_again_after_marks =
      options.mark_cast_shadows && !HasPointLights(out.sample) && options.reuse_band_solves;
  const bool keep_fine_normals =
      fine_factor > 1 && (fine_near_rounds || (options.mark_cast_shadows && !solve_again_after_marks));
  // The clusters on the finer grid (StageOptions::fit_clusters_on_fine_grid), as one band fits them
  // on its whole fine stack (supersampled_reconstruction.h). Not for a tilted view: its fine solves
  // read the top view on the face's plane, and one band fits that case on the maps' grid too.
  const bool clusters_on_fine_grid = fine_fit && options.fit_clusters_on_fine_grid && !NeedsReliefRegistration(out.sample);
  // The last photometric stereo sweep is the first when neither marks nor near-light rounds follow,
  // else the marked one (distant lights, near ones not refined); rounds gather nothing.
  const bool rounds_follow = HasPointLights(out.sample) && ps_options.refine_height;
  const bool marks_follow = options.mark_cast_shadows && !rounds_follow;
  const bool first_sweep_is_last = !rounds_follow && !marks_follow;
  const bool first_sweep_gathers = clusters_on_fine_grid && first_sweep_is_last;
  keep_last_fine_solve = fine_fit && !rounds_follow && options.reuse_band_solves;
  if (choose_roughness) {
    const double start = SteadySeconds();
    const double roughness = reconstruction::ChooseDiffuseRoughness(out.sample, ps_options);
    solve_seconds += SteadySeconds() - start;
    if (roughness < 0.0) {
      ps_options.diffuse_model = reconstruction::DiffuseModel::kLambert;
      LogInfo() << "photometric stereo: Lambert's law fits the sample better than any Burley diffuse lobe";
    } else {
      ps_options.diffuse_roughness = roughness;
      LogInfo() << "photometric stereo: Burley diffuse lobe, roughness " << roughness << " (least residual on the sample)";
    }
    ps = solve_sweep(nullptr, nullptr, nullptr, "photometric stereo",
                     {.keep_fine = keep_fine_normals, .gather_fine_sample = first_sweep_gathers,
                      .last_sweep = first_sweep_is_last, .keep_whole = solve_again_after_marks});
  } else if (fine_factor > 1) {
    // On the fine bands, the sample taken above.
    ps = solve_sweep(nullptr, nullptr, nullptr, "photometric stereo",
                     {.keep_fine = keep_fine_normals, .gather_fine_sample = first_sweep_gathers,
                      .last_sweep = first_sweep_is_last, .keep_whole = solve_again_after_marks});
  } else {
    // Sweep 1: the anchor plane, and the sample; the side's checks on the sample.
    ps = solve_sweep(nullptr, nullptr, &out.sample, "photometric stereo");
    if (keep_checked_frames()) ps = solve_sweep(nullptr, nullptr, nullptr, "photometric stereo");  // without the frames left out
  }
  const bool near = HasPointLights(out.sample);

  // Distant lights (or near ones without refinement): integrate, mark, one more sweep
  // (RunPhotometricStereoMarkingShadows band by band). The solve stays at the anchor plane.
  if (options.mark_cast_shadows && !(near && ps_options.refine_height)) {
    reconstruction::IntegrationOptions integration = ps_options.integration;
    integration.pitch_mm = grid.pitch_mm;
    const double start = SteadySeconds();
    shadow_height = reconstruction::IntegrateNormals(ps.normal, ps.confidence, integration).height_mm;
    // The first sweep's fine normals and confidence: kept whole in fine_first, else alone.
    const bool whole_kept = !fine_first.normal.empty();
    const Image& fine_normal = whole_kept ? fine_first.normal : fine_last_normal;
    if (!fine_normal.empty()) {
      integration.pitch_mm = fine_calibration.grid.pitch_mm;
      fine_shadow_height =
          reconstruction::IntegrateNormals(fine_normal, whole_kept ? fine_first.confidence : fine_last_confidence,
                                           integration)
              .height_mm;
      fine_last_normal = Image();
      fine_last_confidence = Image();
    }
    shadow_seconds += SteadySeconds() - start;
    const PhotometricStereoResult* earlier = solve_again_after_marks ? (fine_factor > 1 ? &fine_first : &ps) : nullptr;
    ps = solve_sweep(nullptr, &shadow_height, nullptr, "photometric stereo (cast shadows left out)",
                     {.gather_fine_sample = clusters_on_fine_grid, .last_sweep = true, .earlier = earlier});
  }

  // Near point lights: RunPhotometricStereo's refinement, one sweep per round.
  Image fine_near_height;  // on fine bands: the kept round's heights on the fine grid (else empty)
  bool near_rounds_capped = false;
  int near_round_limit = ps_options.max_near_iterations;
  if (near && ps_options.refine_height) {
    // Each round re-reads and re-solves every band; with the DCT integrator at most
    // kMaxBandedNearRounds rounds run (the fast preset's limit), whatever the preset asks.
    constexpr int kMaxBandedNearRounds = 3;
    const int max_rounds = bands.count() > 1 && ps_options.integration.method == reconstruction::Integrator::kDct
                               ? std::min(ps_options.max_near_iterations, kMaxBandedNearRounds)
                               : ps_options.max_near_iterations;
    near_rounds_capped = max_rounds < ps_options.max_near_iterations;
    near_round_limit = max_rounds;
    if (near_rounds_capped)
      LogInfo() << "photometric stereo: near-light rounds capped at " << max_rounds << " in a run of " << bands.count()
                << " bands (preset: " << ps_options.max_near_iterations << ")";
    reconstruction::PhotometricStereoOptions round_options = ps_options;
    round_options.max_near_iterations = max_rounds;
    // Each solve is one sweep of every band, marked from the round's heights; a rejected round
    // gives back the kept round's shadow counts (the bands are marked again below).
    // On fine bands the round's heights are integrated on the whole fine grid from the last sweep's
    // fine normals, as one band integrates its fine stack's, and the fine bands are solved and
    // marked at them: the maps' heights taken there bilinearly are too smooth for a yarn's walls
    // (plain on the near rig at 3x in 3 bands: normals 1.297 -> 1.154 deg, base colour dE 1.17 ->
    // 0.76; one band 1.157 and 0.83; docs/process.md). The loop itself (integration, convergence) stays on the
    // maps' grid. 24 B a fine pixel while it runs: the fine normals, confidence and two heights.
    reconstruction::IntegrationOptions fine_integration = ps_options.integration;
    fine_integration.pitch_mm = fine_calibration.grid.pitch_mm;
    Image fine_round_height, fine_kept_height;  // the round's fine heights and the round's before
    bool last_round_rejected = false;  // the kept round is the one before the last sweep
    reconstruction::CastShadowCounts counts_before_sweep = shadow_counts;
    const double solve_before = solve_seconds, shadow_before = shadow_seconds, start = SteadySeconds();
    ps = reconstruction::RefineNearLightHeights(
        std::move(ps), round_options, grid.pitch_mm,
        [&](const Image& height) {
          counts_before_sweep = shadow_counts;
          if (fine_near_rounds) {
            fine_kept_height = std::move(fine_round_height);
            fine_round_height =
                reconstruction::IntegrateNormals(fine_last_normal, fine_last_confidence, fine_integration).height_mm;
          }
          return solve_sweep(&height, options.mark_cast_shadows ? &height : nullptr, nullptr,
                             "photometric stereo (near-light round)",
                             {.keep_fine = fine_near_rounds, .fine_heights = fine_near_rounds ? &fine_round_height : nullptr});
        },
        [&](const Image&, bool kept_round) {
          if (!kept_round) return;
          last_round_rejected = true;
          shadow_counts = counts_before_sweep;
          if (fine_near_rounds) fine_round_height = std::move(fine_kept_height);
        });
    // The kept round's fine heights: the fit's fine bands are solved and marked at them, and the
    // maps' heights are their block means, each weighted by its share of the surface (from the last
    // sweep's fine normals; no weights when the parallax is off), as one band's are
    // (AveragePhotometricStereoOntoMaps of its fine side): the rounds' heights, integrated on the
    // maps' grid from the averaged normals, miss the steps between a map pixel's facets.
    if (ps.near_iterations > 0 && !fine_round_height.empty()) {
      fine_near_height = std::move(fine_round_height);
      ps.height_mm = BlockWeightedMean(fine_near_height, SurfaceAreaWeights(fine_last_normal, options.integration.parallax),
                                       fine_factor, grid.pitch_mm);
    }
    // The last sweep's fine normals are the kept round's unless that round was rejected: the
    // facets, without solving the fine bands again.
    if (fit_facets && fine_near_rounds && !last_round_rejected) {
      facet_normals = std::move(fine_last_normal);
      facet_albedo = std::move(fine_last_albedo);
    }
    fine_last_normal = Image();
    fine_last_confidence = Image();
    fine_last_albedo = Image();
    // The sweeps timed their marks into shadow_seconds; the rest (solves, integrations) is
    // photometric stereo's.
    solve_seconds = solve_before + (SteadySeconds() - start) - (shadow_seconds - shadow_before);
  }
  if (options.mark_cast_shadows && near && ps_options.refine_height && ps.near_iterations > 0) shadow_height = ps.height_mm;
  if (near && ps.height_mm.empty()) {
    ps.height_mm = Image(grid.width, grid.height, 1, static_cast<float>(ps_options.integration.mean_height_mm), grid.pitch_mm);
  }
  ps.diffuse_roughness =
      ps_options.diffuse_model == reconstruction::DiffuseModel::kBurley ? ps_options.diffuse_roughness : -1.0;
  const int ps_builds = bands.builds() + fine_bands.builds();
  const std::string fine_detail =
      fine_factor > 1 ? " (" + std::to_string(fine_bands.builds()) + " of them on the " + std::to_string(fine_factor) + "x finer " +
                  std::to_string(fine_calibration.grid.width) + "x" + std::to_string(fine_calibration.grid.height) +
                  " grid, for --ps-supersample)"
            : "";
  report->steps.push_back({"rectify " + side, true,
                           std::to_string(frames.size()) + " observations on a " + std::to_string(grid.width) + "x" +
                               std::to_string(grid.height) + " grid in " + std::to_string(plan.bands) + " bands of " +
                               std::to_string(plan.band_rows) + " rows, built " + std::to_string(ps_builds) +
                               " times for photometric stereo" + fine_detail,
                           bands.build_seconds() + fine_bands.build_seconds()});
  const std::string solve_name = "photometric stereo (" + reconstruction::PsSolverName(ps_options.solver) + ", tiled" +
                                 (fine_factor > 1 ? ", " + std::to_string(fine_factor) + "x finer grid)" : ")");
  report->steps.push_back({solve_name, true,
                           (near ? "near point lights, height refined " + std::to_string(ps.near_iterations) +
                                       " rounds (one sweep over the bands each" +
                                       (near_rounds_capped ? ", at most " + std::to_string(near_round_limit) + " in bands)" : ")")
                                 : std::string("distant lights")) +
                               (fine_factor > 1 ? "; each band solved on the finer grid, its unit normals averaged onto the maps' grid"
                                      : ""),
                           solve_seconds});
  if (!near) {
    report->steps.push_back({"near-light refinement", false,
                             "distant lights: one light direction per frame, no per-pixel light vectors to refine", 0.0});
  }
  out.reconstruction.photometric_stereo = std::move(ps);
  // The fit's sample and every band built from here on carry the final marks.
  if (!shadow_height.empty()) mark(shadow_height, grid, &out.sample);
  // A tilted view (relief_registration.h): the solves above used the most vertical view alone, on
  // the face's plane. Their heights now place every grid pixel at its own height: the bands are
  // built again there (the tilted views registered on the relief, their hidden pixels marked), and
  // one more sweep solves photometric stereo on them and gathers the fit's sample anew, as the
  // one-band path reconstructs again on its relief stack. The solve keeps the heights the last one
  // used for the near lights' vectors (no new near-light rounds: the top view moves by hundredths
  // of a pixel).
  if (NeedsReliefRegistration(out.sample)) {
    const double relief_start = SteadySeconds();
    const int builds_before = bands.builds();
    RunReport first_pass;  // the heights of the plane's solve place the relief; the run keeps the final ones
    IntegrateSide(grid, near, options, alpha, &out.reconstruction, &first_pass, progress);
    Image z = ReliefHeightsMm(out.reconstruction.height_mm, out.reconstruction.valid, prepared.calibration.surface_z_mm);
    const auto [lo, hi] = std::minmax_element(z.plane(0).begin(), z.plane(0).end());
    const double z_lo = *lo, z_hi = *hi;
    bands.PutOnRelief(std::move(z));
    if (fine_factor > 1) {
      // The fine solves read the most vertical view on the face's plane, as the one-band path's do
      // (that view moves by hundredths of a pixel on the relief): only the fit's sample is taken anew.
      out.sample = sample_sweep("fit sample (on the relief)");
    } else {
      PhotometricStereoResult plane_ps = std::move(out.reconstruction.photometric_stereo);
      Image solved_at = std::move(plane_ps.height_mm);  // empty for distant lights: the anchor plane
      // The plane's maps are released before the sweep; only its counts and round figures are kept.
      plane_ps.normal = plane_ps.albedo = plane_ps.confidence = plane_ps.condition_number = plane_ps.used_lights = Image();
      out.reconstruction = SideReconstruction();
      Stack sample;
      PhotometricStereoResult relief_ps = solve_sweep(solved_at.empty() ? nullptr : &solved_at,
                                                      shadow_height.empty() ? nullptr : &shadow_height, &sample,
                                                      "photometric stereo (on the relief)");
      relief_ps.height_mm = std::move(solved_at);
      relief_ps.near_iterations = plane_ps.near_iterations;
      relief_ps.diffuse_roughness = plane_ps.diffuse_roughness;
      relief_ps.last_normal_change_deg = plane_ps.last_normal_change_deg;
      out.reconstruction.photometric_stereo = std::move(relief_ps);
      out.sample = std::move(sample);
    }
    if (!shadow_height.empty()) mark(shadow_height, grid, &out.sample);  // the sweeps mark a band after sampling it
    const int top = MostVerticalView(out.sample);
    char detail[360];
    std::snprintf(detail, sizeof detail,
                  "heights from view %s alone (%.1f deg from the vertical): %.3f to %.3f mm, top on the face z = %.3f "
                  "mm; every view rectified at them, in %d bands (%d more builds); %.2f %% of the tilted views' "
                  "pixels hidden by the relief",
                  out.sample.views.at(static_cast<std::size_t>(top)).camera_id.c_str(), ViewTiltDeg(out.sample, top),
                  z_lo, z_hi, prepared.calibration.surface_z_mm, bands.count(), bands.builds() - builds_before,
                  100.0 * bands.hidden_share());
    report->steps.push_back({"relief registration " + side, true, detail, SteadySeconds() - relief_start});
  }
  out.reconstruction.cast_shadow_share = shadow_height.empty() ? 0.0 : shadow_counts.share();
  out.reconstruction.cast_shadow_solved_again_share = shadow_height.empty() || near ? -1.0 : solved_again_share;
  IntegrateSide(grid, near, options, alpha, &out.reconstruction, report, progress);
  const SideReconstruction& geometry = out.reconstruction;

  // Fit: clusters on the sample, then the per-pixel step band by band.
  ReportObliqueView(out.sample, report);
  double start = SteadySeconds();
  const double build_before_fit = bands.build_seconds() + fine_bands.build_seconds();
  // --ps-supersample: a fine band with the last sweep's normals and albedo (kept above, else solved
  // again as the last sweep solved it), its heights from the whole fine grid's: the surface's
  // (bilinear), the last solve's for the near lights' vectors (empty: the anchor plane) and the
  // marks'. 4 B a fine pixel each, made when a fine pass below needs them (the facets' solve needs
  // the last two, not the surface's).
  const MetricGrid& fine_grid = fine_calibration.grid;
  Image fine_surface_height, fine_solve_height, fine_marks;
  if (fine_fit || top_view_fit || (fit_facets && facet_normals.empty())) {
    if (fine_fit || top_view_fit) fine_surface_height = UpsampleLinear(geometry.height_mm, fine_factor);
    if (!fine_near_height.empty()) {
      fine_solve_height = fine_near_height;  // near lights' last round on the fine grid
    } else if (!geometry.photometric_stereo.height_mm.empty()) {
      fine_solve_height = UpsampleLinear(geometry.photometric_stereo.height_mm, fine_factor);
    }
    // The fine heights' marks when they were integrated (distant lights, near lights' rounds), no
    // longer needed otherwise.
    if (!shadow_height.empty()) {
      if (!fine_near_height.empty()) {
        fine_marks = std::move(fine_near_height);
      } else {
        fine_marks = fine_shadow_height.empty() ? UpsampleLinear(shadow_height, fine_factor) : std::move(fine_shadow_height);
      }
    }
  }
  // Its normals and albedo (the surface's heights are the caller's to add). `top_view_only`: the
  // band is built from the top camera's frames alone (top_camera), and solved on all it holds.
  std::vector<std::size_t> top_frames;
  if (!top_camera.empty()) {
    std::copy_if(frames.begin(), frames.end(), std::back_inserter(top_frames), [&](std::size_t index) {
      return prepared.capture.manifest().frames[index].camera == top_camera;
    });
  }
  reconstruction::PhotometricStereoOptions top_ps_options = ps_options;
  top_ps_options.view = -1;  // a band of the top view's frames holds that view alone
  auto fine_band_surface = [&](int b, Stack* band, bool with_fibre_turns = true,
                               bool top_view_only = false) -> fitting::SurfaceGeometry {
    *band = fine_bands.Build(top_view_only ? top_frames : frames, b);
    const int row0 = fine_bands.Row0(b), rows = fine_bands.Rows(b);
    if (!fine_band_marks.empty()) {
      const double start = SteadySeconds();
      fine_band_marks.Apply(row0, band);
      shadow_seconds += SteadySeconds() - start;
    } else if (!fine_marks.empty()) {
      mark(fine_marks, fine_grid, band);
    }
    fitting::SurfaceGeometry surface;
    if (!fine_fit_normal.empty()) {
      surface = {CropRows(fine_fit_normal, row0, rows), CropRows(fine_fit_albedo, row0, rows), Image(), Image(), Image(), 1};
    } else if (!facet_albedo.empty()) {  // a tilted view's last near-light round: the facets and their albedo
      surface = {CropRows(facet_normals, row0, rows), CropRows(facet_albedo, row0, rows), Image(), Image(), Image(), 1};
    } else {
      PhotometricStereoResult solved = reconstruction::SolvePhotometricStereoAt(
          *band, top_view_only ? top_ps_options : ps_options,
          fine_solve_height.empty()
              ? Image(fine_grid.width, rows, 1, static_cast<float>(ps_options.integration.mean_height_mm), fine_grid.pitch_mm)
              : CropRows(fine_solve_height, row0, rows));
      surface = {std::move(solved.normal), std::move(solved.albedo), Image(), Image(), Image(), 1};
    }
    // The fibres' turns of a band, from its own normals (within the window's reach of a band edge,
    // a few fine rows, they differ slightly from one band's).
    if (with_fibre_turns) surface.fibre_turn_deg = FibreTurnsIfFollowed(surface.normals, options);
    return surface;
  };
  // The facets, unless the near-light rounds left them: a tilted view's run has no fine pass of the
  // fit and keeps no other fine solve, so each fine band is solved again as the last sweep solved
  // it (one more sweep of the fine bands; no fibre turns, which the facets do not use).
  if (fit_facets && facet_normals.empty()) {
    if (!fine_fit_normal.empty()) {
      facet_normals = fine_fit_normal;
    } else {
      facet_normals = Image(fine_grid.width, fine_grid.height, 3, 0.0f, fine_grid.pitch_mm);
      for (int b = 0; b < fine_bands.count(); ++b) {
        Stack band;
        PasteRows(fine_band_surface(b, &band, /*with_fibre_turns=*/false, /*top_view_only=*/true).normals,
                  fine_bands.Row0(b), &facet_normals);
        ReportProgress(progress, "fit: facets on the finer grid", static_cast<double>(b + 1) / fine_bands.count());
      }
    }
  }
  // The clusters on the finer grid: the sample gathered by the last photometric stereo sweep (above),
  // else (near lights refined in rounds) in one more sweep of the fine bands, solved as that sweep
  // solved them; its heights from the whole fine grid's.
  fitting::SurfaceGeometry sample_geometry;
  if (clusters_on_fine_grid) {
    if (!fine_sample_gathered) {
      for (int b = 0; b < fine_bands.count(); ++b) {
        Stack band;
        const fitting::SurfaceGeometry band_surface = fine_band_surface(b, &band);
        const int row0 = fine_bands.Row0(b);
        AddToSample(band, row0, fine_step, fine_sample_grid, &fine_sample);
        SampleRows(band_surface.normals, row0, fine_step, fine_sample_grid, &fine_sample_geometry.normals);
        SampleRows(band_surface.albedo, row0, fine_step, fine_sample_grid, &fine_sample_geometry.albedo);
        add_fine_turns(band_surface.fibre_turn_deg, row0);
        ReportProgress(progress, "fit: sample on the finer grid", static_cast<double>(b + 1) / fine_bands.count());
      }
    }
    sample_geometry = std::move(fine_sample_geometry);
    SampleRows(fine_surface_height, 0, fine_step, fine_sample_grid, &sample_geometry.height_mm);
    out.sample = std::move(fine_sample);
  }
  // The fibres' turns on the maps' grid (StageOptions::follow_fibres), read on whole maps as one
  // band reads them, then cropped or sampled like the normals: the fine bands' averaged (above),
  // else (no fine grid, or the clusters on the maps' grid) the maps' own normals'.
  const Image maps_turns = !fine_turns_on_maps.empty() ? std::move(fine_turns_on_maps)
                                                       : FibreTurnsIfFollowed(geometry.photometric_stereo.normal, options);
  if (!clusters_on_fine_grid) {
    SampleRows(geometry.photometric_stereo.normal, 0, step, sample_grid, &sample_geometry.normals);
    SampleRows(geometry.photometric_stereo.albedo, 0, step, sample_grid, &sample_geometry.albedo);
    SampleRows(geometry.height_mm, 0, step, sample_grid, &sample_geometry.height_mm);
    if (!maps_turns.empty()) SampleRows(maps_turns, 0, step, sample_grid, &sample_geometry.fibre_turn_deg);
    if (fit_facets) {
      sample_geometry.fine_normals = SampleFineBlocks(facet_normals, fine_factor, step, sample_grid);
      sample_geometry.fine_factor = fine_factor;
    }
  }
  const fitting::ClusterModel model = fitting::FitClusterModel(out.sample, sample_geometry, options.fit, progress);
  out.fit = fitting::StartPixelMaps(model, grid);
  fitting::PixelTally tally;
  for (int b = 0; b < bands.count(); ++b) {
    Stack band = bands.Build(frames, b);
    if (!shadow_height.empty()) mark(shadow_height, grid, &band);
    const int row0 = bands.Row0(b);
    fitting::FitPixelRows(model, band, BandSurface(geometry, row0, bands.Rows(b), maps_turns, facet_normals, fine_factor),
                          row0, &out.fit, &tally);
    ReportProgress(progress, "fit: pixels", static_cast<double>(b + 1) / bands.count());
  }
  fitting::FinishPixelMaps(model, tally, &out.fit);
  // --ps-supersample: the normals refined once more on the fine bands (as FitSideWithFineNormals
  // does on one band; a tilted view's against its top view alone, as FitSideRefiningTopViewNormals
  // does), their unit normals averaged onto the maps and their heights integrated on the whole fine
  // grid.
  Image fine_height;
  double fine_fit_seconds = 0.0;
  std::string placed;  // what the plan placement moved, for the report
  const bool fine_solves_kept = !fine_fit_normal.empty();
  if ((fine_fit && !out.fit.normals.empty()) || top_view_fit) {
    const double fine_start = SteadySeconds();
    Image fine_normals(fine_grid.width, fine_grid.height, 3, 0.0f, fine_grid.pitch_mm);
    fitting::PixelTally fine_tally;  // the maps' grid's tally is the one reported
    FineColourAverage colour(grid.width, grid.height, fine_factor);  // fine_colour.h
    // Each fine pixel's share of the surface seen along the camera's rays (fine_grid.h), band by
    // band, for the colour, the normals' average and the fine heights (empty: the parallax is off).
    const reconstruction::ViewParallax& parallax = options.integration.parallax;
    Image fine_weights;
    if (parallax.enabled) fine_weights = Image(fine_grid.width, fine_grid.height, 1, 1.0f, fine_grid.pitch_mm);
    // Where each fine pixel's surface point lies in plan (plan_placement.h), by the fine heights
    // the marks came from (integrated on the whole fine grid: a yarn's valley and top apart), else
    // the maps' heights taken there bilinearly.
    const Image fine_valid = UpsampleNearest(geometry.valid, fine_factor);
    const PlanPlacement placement =
        options.place_fine_pixels_on_plan
            ? PlanPlacement(fine_marks.empty() ? fine_surface_height : fine_marks, fine_valid, options.placement_parallax,
                            fine_factor)
            : PlanPlacement();
    placed = PlacementDetail(placement, fine_grid.pitch_mm);
    std::optional<fitting::ClusterModel> top_model;  // a tilted view's: the model for the top view's observations
    for (int b = 0; b < fine_bands.count(); ++b) {
      Stack band;
      fitting::SurfaceGeometry band_surface = fine_band_surface(b, &band, true, /*top_view_only=*/top_view_fit);
      const int row0 = fine_bands.Row0(b), rows = fine_bands.Rows(b);
      band_surface.height_mm = CropRows(fine_surface_height, row0, rows);
      if (top_view_fit && !top_model) top_model = ModelForTopViewNormals(model, out.sample, band);
      const fitting::ClusterModel& refining = top_model ? *top_model : model;
      fitting::FitResult band_fit = fitting::StartPixelMaps(refining, band.grid);
      fitting::FitPixelRows(refining, band, band_surface, 0, &band_fit, &fine_tally);
      PasteRows(band_fit.normals, row0, &fine_normals);
      const Image band_weights = SurfaceAreaWeights(band_fit.normals, parallax, row0);
      if (!band_weights.empty()) PasteRows(band_weights, row0, &fine_weights);
      // The top view's pass writes the normals alone (top_view_normals.h).
      if (options.base_colour_from_fine_grid && !top_view_fit) {
        colour.Add(band_fit.base_color, band_fit.cluster_id, row0, band_weights, placement);
      }
      ReportProgress(progress, "fit: pixels on the finer grid", static_cast<double>(b + 1) / fine_bands.count());
    }
    if (options.base_colour_from_fine_grid && !top_view_fit) colour.ApplyTo(out.fit.cluster_id, &out.fit.base_color);
    fine_fit_normal = fine_fit_albedo = facet_albedo = Image();  // before the fine integration's work space
    fine_band_marks = BandShadowMarks();
    fine_height = IntegrateFineRefinedNormals(std::move(fine_normals), fine_valid, fine_weights, geometry.valid,
                                              fine_factor, grid.pitch_mm, near, options, progress, placement,
                                              &out.fit.normals, top_view_fit ? &geometry.height_mm : nullptr);
    fine_fit_seconds = SteadySeconds() - fine_start;
  }
  out.fit.times.total_s = SteadySeconds() - start;
  // The per-pixel step refined every pixel's normal band by band into the full-size map; the whole
  // normal map is in memory already, so the height is integrated again as in the untiled path.
  out.fitted_normals = fine_height.empty()
                           ? AdoptFittedNormals(&out.fit, grid, near, options, &out.reconstruction, report, progress)
                           : AdoptFineFittedNormals(&out.fit, std::move(fine_height), &out.reconstruction, report,
                                                    top_view_fit);
  std::string sampled;  // where the clusters' sample came from
  if (clusters_on_fine_grid) {
    const std::string block = std::to_string(step * fine_factor);
    sampled = "the " + std::to_string(fine_factor) + "x finer grid, one pixel in " + block + " x " + block;
  } else {
    if (fine_factor > 1) sampled = "the maps' grid, ";
    sampled += step == 1 ? std::string("every pixel") : "every " + std::to_string(step) + "th row and column";
  }
  std::string detail = std::to_string(out.fit.clusters.size()) + " clusters fitted on " + sampled +
                       ", pixels band by band (band rebuild " +
                       std::to_string(bands.build_seconds() + fine_bands.build_seconds() - build_before_fit) +
                       " s included)";
  if (fit_facets) detail += FacetsDetail(fine_factor);
  if (top_view_fit) {
    detail += TopViewNormalsDetail(fine_factor, top_camera, fine_fit_seconds) + placed;
  } else if (fine_fit_seconds > 0.0) {
    char fine_detail[160];
    std::snprintf(fine_detail, sizeof fine_detail, "; normals refined on the %dx finer grid (%.2f s of it; %s)", fine_factor,
                  fine_fit_seconds,
                  fine_solves_kept ? "the last sweep's fine solves kept" : "each fine band solved again as the last sweep did");
    detail += fine_detail + placed;
  }
  ReportFitStep(out.fit, std::move(detail), SteadySeconds() - start, report);

  // Residual map: the observations FitResidualMap would take from the whole stack, band by band.
  start = SteadySeconds();
  const int n = static_cast<int>(frames.size());
  const int used = std::min(n, std::max(1, residual_observations));
  std::vector<std::size_t> residual_frames;
  for (int k = 0; k < used; ++k) residual_frames.push_back(frames[static_cast<std::size_t>(k) * n / used]);
  out.residual = Image(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
  double residual_sum = 0.0;
  std::size_t residual_pixels = 0;
  for (int b = 0; b < bands.count(); ++b) {
    Stack band = bands.Build(residual_frames, b);
    if (!shadow_height.empty()) mark(shadow_height, grid, &band);
    const int row0 = bands.Row0(b), rows = bands.Rows(b);
    double mean = 0.0;
    std::size_t pixels = 0;
    PasteRows(FitResidualMap(BandFit(out.fit, row0, rows), band, BandSide(geometry, row0, rows, facet_normals, fine_factor),
                             used, &mean, &pixels),
              row0, &out.residual);
    residual_sum += mean * static_cast<double>(pixels);
    residual_pixels += pixels;
  }
  out.residual_mean = residual_pixels ? residual_sum / static_cast<double>(residual_pixels) : 0.0;
  report->steps.push_back({"residual map", true, std::to_string(used) + " observations, band by band", SteadySeconds() - start});
  // Marking time of every sweep (photometric stereo, fit, residual), with the integration it needed.
  report->steps.push_back(CastShadowStep(options, out.reconstruction.cast_shadow_share, near, shadow_seconds,
                                         out.reconstruction.cast_shadow_solved_again_share));

  // Held-out lights: CheckHeldOutLights band by band (marks from the final heights, timed here).
  if (!held_out_frames.empty()) {
    start = SteadySeconds();
    HeldOutSums sums;
    for (int b = 0; b < bands.count(); ++b) {
      Stack band = bands.Build(held_out_frames, b);
      if (options.mark_cast_shadows && !geometry.height_mm.empty()) {
        reconstruction::MarkCastShadows(geometry.height_mm, grid, &band, options.cast_shadows);
      }
      const int row0 = bands.Row0(b), rows = bands.Rows(b);
      sums.Add(BandFit(out.fit, row0, rows), band, BandSurface(geometry, row0, rows, Image(), facet_normals, fine_factor));
      ReportProgress(progress, "held-out lights", static_cast<double>(b + 1) / bands.count());
    }
    out.held_out = sums.Finish(SteadySeconds() - start);
  }
  return out;
}

}  // namespace u3mscan

#pragma once
// Registration of tilted views on the sample's relief.
//
// A camera tilted by theta from the vertical sees a surface point z mm above the plane the grid
// lies in shifted by z tan(theta) along its tilt: a velvet pile whose heights span 0.25 mm, seen at
// 60 deg, moves by up to 0.43 mm (5 px at 300 dpi) from one yarn to the next, so the oblique
// view's observations of a grid pixel would be of another part of the fabric. The plane of the
// sample's face (CalibrationResult::surface_z_mm) takes out the mean offset; the relief itself
// needs heights, which only the reconstruction gives. So a capture with a tilted view is
// reconstructed twice: once from the most vertical view alone (its parallax is the relief times
// the tangent of a few degrees: hundredths of a pixel), whose integrated heights then place every
// grid pixel at its own height when the stack is built again from all views (BuildStack's
// `surface_z_mm`).

#include <string>

#include "core/image.h"
#include "core/stack.h"
#include "pipeline/stages.h"

namespace u3mscan {

// A view whose axis to the grid's centre is tilted more than this from the vertical (deg) is
// registered on the relief. The top cameras of the rigs sit within a degree or two of it.
inline constexpr double kReliefRegistrationMinTiltDeg = 10.0;

// Tilt (deg) of the line from the grid's centre (on its plane) to view's camera centre.
double ViewTiltDeg(const Stack& stack, int view);
// Index into stack.views of the least tilted view; -1 when the stack has no view.
int MostVerticalView(const Stack& stack);
// True when the stack has two views or more and one of them is tilted beyond
// kReliefRegistrationMinTiltDeg.
bool NeedsReliefRegistration(const Stack& stack);

// The top of the relief `height_mm` (integrated, known up to a constant): the 0.999 quantile of
// its finite heights where `valid` (1 plane, >= 0.5; empty: every pixel), so that a few integration
// spikes do not move it. NaN when there is no such height.
double ReliefTopMm(const Image& height_mm, const Image& valid);

// Absolute heights of the relief (mm, world z): `height_mm` (integrated, known up to a constant)
// moved so that its top lies on the sample's face `surface_z_mm` (the manifest's thickness is the
// sample's highest point, as a gauge reads it). The top is ReliefTopMm(height_mm, valid).
Image ReliefHeightsMm(const Image& height_mm, const Image& valid, double surface_z_mm);

// Grid pixels that a tilted view cannot see past the relief (a steep face turned away from it,
// or a hollow behind a ridge) are marked kOutOfView in that view's observations: its camera pixel
// there shows another point of the fabric. The test is the cast-shadow march
// (reconstruction/cast_shadows.h) with the camera's centre as the point of light, over
// `surface_z_mm` (the absolute heights, ReliefHeightsMm). Returns the share of the tilted views'
// grid pixels marked (0 when there is no tilted view).
double MarkHiddenFromTiltedViews(const Image& surface_z_mm, Stack* stack);
// The same for a stack whose grid is a band of `height_grid`, the grid `surface_z_mm` covers (scans
// in bands: a band's pixels can be hidden by relief outside it).
double MarkHiddenFromTiltedViews(const Image& surface_z_mm, const MetricGrid& height_grid, Stack* stack);

// Normals of a capture with a tilted view: photometric stereo from the most vertical view alone
// (options->photometric_stereo.view) and no per-pixel normal refinement in the fit
// (fit.refine_pixel_normals off; the cluster fits still use every view). A tilted camera's
// footprint is 1/cos(tilt) times longer along its tilt and its shading holds the view-dependent
// lobes; with every view in photometric stereo and in the refinement the normals leaned and
// integrated into a ramp (docs/process.md, "Relief registration": velvet height 11 -> 2.4 %,
// plain 145 -> 8 % of the range). With a finer grid the normals are refined afterwards against
// that view alone (top_view_normals.h).
void UseTheMostVerticalViewForNormals(const Stack& stack, StageOptions* options);

// The report's step for the fitted normals a capture with a tilted view does not use (no finer
// grid, or --no-top-view-refinement: top_view_normals.h).
StepRecord TiltedViewNormalsStep();

// The grid and the views (no observations) of a side's stack, in the order BuildStack gives them
// (cameras by their first sample frame of the side): for decisions taken before any stack is built
// (scans in bands).
Stack SideViews(const PreparedCapture& prepared, const std::string& side);

// The side's stack built again on the relief: `on_plane` (BuildSideStack on the face's plane,
// held-out observations already taken out) is reconstructed from its most vertical view alone, and
// the frames are read and rectified again at the heights that gives (ReliefHeightsMm), and what
// the tilted views cannot see is marked (MarkHiddenFromTiltedViews). Reports
// one step, "relief registration SIDE". `on_plane` is released before the frames are read again.
Stack BuildSideStackOnRelief(const PreparedCapture& prepared, const std::string& side, const StageOptions& options,
                             const Image& alpha, Stack on_plane, RunReport* report,
                             const ProgressCallback& progress = {});

}  // namespace u3mscan

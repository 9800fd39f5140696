#pragma once
// Internals of the scene presets: a fabric is a SurfaceModel, a pure function of the position on
// the sample (mm) and the seed. scene.cc samples it on the grid in parallel and derives normals.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "datasets_synthetic/scene.h"

namespace u3mscan::synthetic::internal {

// Everything a scene says about one point of the fabric surface.
struct SurfacePoint {
  float height_mm = 0.0f;
  float base_color[3] = {0.5f, 0.5f, 0.5f};  // linear RGB
  float roughness = 0.5f;
  float specular = 0.5f;
  float specular_tint = 0.0f;
  float sheen = 0.0f;
  float sheen_tint = 0.0f;
  float metallic = 0.0f;
  float anisotropic = 0.0f;
  float alpha = 1.0f;
  // In-plane fibre direction (world x, y); need not be unit, (0, 0) means "x axis".
  float tangent_x = 1.0f;
  float tangent_y = 0.0f;
};

// Nominal material of a yarn; applied to a SurfacePoint with per-thread variation by the families.
struct YarnMaterial {
  float base_color[3] = {0.5f, 0.5f, 0.5f};
  float roughness = 0.7f;
  float specular = 0.5f;
  float specular_tint = 0.0f;
  float sheen = 0.0f;
  float sheen_tint = 0.0f;
  float anisotropic = 0.0f;
  // Relative spread of the base colour between threads (0.05 = +-5 %) and between fibres.
  float thread_color_variation = 0.0f;
  float fibre_color_variation = 0.0f;
  // Absolute spread of roughness between threads.
  float thread_roughness_variation = 0.0f;
};

// A procedural fabric. Evaluate must be thread-safe and deterministic (no state, no allocation).
class SurfaceModel {
 public:
  virtual ~SurfaceModel() = default;
  virtual SurfacePoint Evaluate(double x_mm, double y_mm) const = 0;
  // Height alone (for normals beyond the grid border); override when cheaper than Evaluate.
  virtual double HeightMm(double x_mm, double y_mm) const { return Evaluate(x_mm, y_mm).height_mm; }
};

// What a preset factory returns: the model and the scene-level truth it declares.
struct SceneSpec {
  std::unique_ptr<SurfaceModel> model;
  ReflectanceModel reflectance = ReflectanceModel::kPrincipled;
  double height_min_mm = 0.0;
  double height_max_mm = 0.0;
  double repeat_x_mm = 0.0;
  double repeat_y_mm = 0.0;
  std::string description;
  std::vector<YarnTruth> yarns;
};

// Copies a material into a point and applies per-thread variation (thread_hash in [0,1)^2 from
// the thread index) and per-fibre variation (fibre_noise in [-1, 1]).
void ApplyYarn(const YarnMaterial& yarn, float thread_u0, float thread_u1, float fibre_noise, SurfacePoint* point);
YarnTruth ToYarnTruth(const std::string& name, const YarnMaterial& yarn, double width_mm, double thickness_mm,
                      double spacing_mm);

// ---- Families (one file each). ----

// Woven fabrics: warp threads run along y, weft along x; pattern[j * repeat_warp + i] says whether
// warp i is over weft j.
struct WeaveSpec {
  int repeat_warp = 2;  // pattern size across warps (x)
  int repeat_weft = 2;  // pattern size across wefts (y)
  std::vector<unsigned char> warp_over;
  double warp_spacing_mm = 0.4;
  double weft_spacing_mm = 0.4;
  double warp_width_mm = 0.4;
  double weft_width_mm = 0.4;
  double warp_thickness_mm = 0.12;  // crown of the cross-section above the yarn axis
  double weft_thickness_mm = 0.12;
  double crimp_mm = 0.06;           // axis above (over) or below (under) the fabric mid-plane
  double slub = 0.0;                // relative thickness variation along a yarn (0.1 = +-10 %)
  double slub_length_mm = 4.0;      // length scale of that variation
  double ply_depth_mm = 0.0;        // depth of the twisted-ply grooves on a yarn crown
  double ply_pitch_mm = 0.5;        // distance between grooves along the yarn
  double twist_angle_deg = 25.0;    // groove angle to the yarn axis
  bool gaps_are_holes = false;      // where no yarn covers: a hole (alpha 0) or the fabric's back
  YarnMaterial warp;
  YarnMaterial weft;
};
SceneSpec MakeWeave(const WeaveSpec& spec, std::uint64_t seed);

// Weave patterns (warp-over matrices).
WeaveSpec PlainPattern();
WeaveSpec TwillPattern(int over, int under);  // over/under per warp, shifted by one per warp
WeaveSpec SatinPattern(int harness, int move);  // warp-faced: warp under one weft in `harness`

struct KnitSpec {
  double wale_spacing_mm = 0.8;    // stitch width (x)
  double course_spacing_mm = 0.6;  // stitch height (y)
  double yarn_width_mm = 0.32;
  double yarn_thickness_mm = 0.16;
  double loop_lift_mm = 0.12;      // a leg rises toward its middle and dips where it passes under
  double ply_depth_mm = 0.015;
  double ply_pitch_mm = 0.35;
  YarnMaterial yarn;
};
SceneSpec MakeKnit(const KnitSpec& spec, std::uint64_t seed);

struct PileSpec {
  double pile_height_mm = 0.6;     // mean height of the fibre tips above the ground
  double tip_roughness_mm = 0.05;  // amplitude of fibre-tip noise
  double tip_scale_mm = 0.15;      // length scale of fibre-tip noise
  double crush_mm = 0.15;          // amplitude of crushed (lower, leaning) regions
  double crush_scale_mm = 6.0;
  YarnMaterial pile;
};
SceneSpec MakePile(const PileSpec& spec, std::uint64_t seed);

struct LaceSpec {
  double net_spacing_mm = 1.4;      // diamond net: threads at +-45 deg
  double net_width_mm = 0.18;
  double net_thickness_mm = 0.07;
  double motif_spacing_mm = 9.0;    // square lattice of round motifs
  double motif_radius_mm = 3.0;
  double cloth_spacing_mm = 0.22;   // dense cloth-work inside a motif
  double gimp_width_mm = 0.5;       // raised outline cord
  double gimp_thickness_mm = 0.3;
  YarnMaterial net;
  YarnMaterial gimp;
};
SceneSpec MakeLace(const LaceSpec& spec, std::uint64_t seed);

// Flat plane, spherical cap and bumps: closed-form geometry with one constant material.
SceneSpec MakeFlat(const YarnMaterial& material);
SceneSpec MakeSphereCap(const YarnMaterial& material, const SceneOptions& options);
SceneSpec MakeBumps(const YarnMaterial& material);

}  // namespace u3mscan::synthetic::internal

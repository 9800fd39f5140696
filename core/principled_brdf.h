#pragma once
// The Principled BRDF (Burley, "Physically-Based Shading at Disney", SIGGRAPH 2012 course notes,
// as corrected in Disney's BRDF Explorer through 2017). The ONE reflectance model u3mscan renders
// (datasets_synthetic) and fits (fitting): both include this header, so a fit can only disagree
// with a render through the data, never through two implementations.
//
// Header-only and templated on the scalar type T so it runs on double, float and ceres::Jet
// (automatic differentiation). Maths calls are unqualified (sqrt, log) so that argument-dependent
// lookup finds Jet's overloads; comparisons only pick branches and never feed a derivative.
//
// Frame: every lobe works in the local shading frame, z = surface normal, x = tangent (direction of
// anisotropy), y = bitangent. L and V are unit vectors from the surface point toward the light and
// the viewer. The BRDF value is in 1/sr; radiance from a light is f * cos_l * E.
//
// The variant is written down in docs/principled-brdf.md.

#include <Eigen/Core>
#include <cmath>

namespace u3mscan {

template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;

// Parameters of the model, all in [0, 1], base colour in linear RGB.
template <typename T>
struct PrincipledParams {
  Vec3<T> base_color = Vec3<T>(T(0.8), T(0.8), T(0.8));
  T metallic = T(0);
  T subsurface = T(0);
  T specular = T(0.5);
  T roughness = T(0.5);
  T specular_tint = T(0);
  T anisotropic = T(0);
  T sheen = T(0);
  T sheen_tint = T(0);
  T clearcoat = T(0);
  T clearcoat_gloss = T(1);
};

namespace brdf {

inline constexpr double kPi = 3.14159265358979323846;
// Smallest GGX alpha (Burley: max(0.001, ...)); keeps D finite for a perfect mirror.
inline constexpr double kMinAlpha = 0.001;
// Guard for normalising a half vector whose length is ~0 (L = -V, never above the horizon).
inline constexpr double kTinyLength = 1e-12;

template <typename T>
T Mix(const T& a, const T& b, const T& t) {
  return a + (b - a) * t;
}

template <typename T>
Vec3<T> Mix(const Vec3<T>& a, const Vec3<T>& b, const T& t) {
  return a + (b - a) * t;
}

// True when `x` is exactly 0, and for an automatic-differentiation Jet (a value `a` and a
// derivative vector `v`) so is every derivative. A lobe weighted by such an x adds exactly 0 to
// the BRDF and to each of its derivatives, so EvaluatePrincipled leaves it out: the same result to
// the last bit (the lobes are finite above the horizon), without its cost.
template <typename T>
bool IsExactlyZero(const T& x) {
  if constexpr (requires { x.a; x.v; }) {
    return x.a == 0.0 && (x.v.array() == 0.0).all();
  } else {
    return x == T(0);
  }
}

// Clamp to [0, 1]; the branch picks a value, so Jet derivatives stay those of the chosen value.
template <typename T>
T Clamp01(const T& x) {
  if (x < T(0)) return T(0);
  if (x > T(1)) return T(1);
  return x;
}

// Schlick weight SW(u) = (1 - u)^5 (Burley 2012, eq. for the Fresnel and retro-reflection terms).
template <typename T>
T SchlickWeight(const T& u) {
  const T m = Clamp01(T(1) - u);
  const T m2 = m * m;
  return m2 * m2 * m;
}

// Luminance weights of the tint colour (Burley 2012): what "luminance" means wherever the fit and
// the colour code speak of a base colour's brightness.
inline constexpr double kTintLumR = 0.3, kTintLumG = 0.6, kTintLumB = 0.1;
template <typename T>
T TintLuminance(const Vec3<T>& rgb) {
  return T(kTintLumR) * rgb(0) + T(kTintLumG) * rgb(1) + T(kTintLumB) * rgb(2);
}

// Tint colour: base colour normalised by its luminance, white when black.
template <typename T>
Vec3<T> TintColor(const Vec3<T>& base_color) {
  const T lum = TintLuminance(base_color);
  if (lum > T(0)) return base_color / lum;
  return Vec3<T>(T(1), T(1), T(1));
}

// Burley diffuse with retro-reflection (Burley 2012, section 5.3, eq. 3), without the C/pi factor.
template <typename T>
T DisneyDiffuse(const T& cos_l, const T& cos_v, const T& cos_d, const T& roughness) {
  const T fd90 = T(0.5) + T(2) * roughness * cos_d * cos_d;
  return (T(1) + (fd90 - T(1)) * SchlickWeight(cos_l)) * (T(1) + (fd90 - T(1)) * SchlickWeight(cos_v));
}

// Hanrahan-Krueger-inspired subsurface approximation (Burley 2012, BRDF Explorer "ss" term),
// without the C/pi factor. cos_l + cos_v > 0 is guaranteed by the caller (both above horizon).
template <typename T>
T DisneySubsurface(const T& cos_l, const T& cos_v, const T& cos_d, const T& roughness) {
  const T fss90 = roughness * cos_d * cos_d;
  const T fss = (T(1) + (fss90 - T(1)) * SchlickWeight(cos_l)) * (T(1) + (fss90 - T(1)) * SchlickWeight(cos_v));
  return T(1.25) * (fss * (T(1) / (cos_l + cos_v) - T(0.5)) + T(0.5));
}

// GGX alphas from roughness and anisotropy (Burley 2012, addendum B.2): alpha = roughness^2,
// stretched by aspect = sqrt(1 - 0.9 anisotropic), never below kMinAlpha.
template <typename T>
void AnisotropicAlphas(const T& roughness, const T& anisotropic, T* alpha_x, T* alpha_y) {
  using std::sqrt;
  const T aspect = sqrt(T(1) - T(0.9) * anisotropic);
  const T r2 = roughness * roughness;
  *alpha_x = r2 / aspect;
  *alpha_y = r2 * aspect;
  if (*alpha_x < T(kMinAlpha)) *alpha_x = T(kMinAlpha);
  if (*alpha_y < T(kMinAlpha)) *alpha_y = T(kMinAlpha);
}

// Anisotropic GTR2 (GGX) normal distribution D (Burley 2012, addendum B.2, eq. 13). H in local frame.
template <typename T>
T Gtr2AnisotropicD(const Vec3<T>& h, const T& alpha_x, const T& alpha_y) {
  const T hx = h(0) / alpha_x;
  const T hy = h(1) / alpha_y;
  const T s = hx * hx + hy * hy + h(2) * h(2);
  return T(1) / (T(kPi) * alpha_x * alpha_y * s * s);
}

// Separable anisotropic Smith GGX masking for one direction, with the 1/(2 cos) of the microfacet
// denominator folded in (BRDF Explorer smithG_GGX_aniso). The product for L and V is G/(4 cos_l cos_v).
template <typename T>
T SmithGgxAnisotropicG1(const Vec3<T>& w, const T& alpha_x, const T& alpha_y) {
  using std::sqrt;
  const T wx = w(0) * alpha_x;
  const T wy = w(1) * alpha_y;
  return T(1) / (w(2) + sqrt(wx * wx + wy * wy + w(2) * w(2)));
}

// Specular reflectance at normal incidence (Burley 2012, section 5.5): 0.08 * specular, tinted
// toward the base colour by specular_tint, and the base colour itself for metals.
template <typename T>
Vec3<T> SpecularF0(const PrincipledParams<T>& p) {
  const Vec3<T> white(T(1), T(1), T(1));
  const Vec3<T> dielectric = Mix(white, TintColor(p.base_color), p.specular_tint) * (T(0.08) * p.specular);
  return Mix(dielectric, p.base_color, p.metallic);
}

// Schlick Fresnel toward white at grazing cos_d.
template <typename T>
Vec3<T> SchlickFresnel(const Vec3<T>& f0, const T& cos_d) {
  return Mix(f0, Vec3<T>(T(1), T(1), T(1)), SchlickWeight(cos_d));
}

// Sheen (Burley 2012, section 5.4): a grazing retro-reflective lobe, SW(cos_d) sheen Csheen.
template <typename T>
Vec3<T> SheenLobe(const PrincipledParams<T>& p, const T& cos_d) {
  const Vec3<T> white(T(1), T(1), T(1));
  return Mix(white, TintColor(p.base_color), p.sheen_tint) * (SchlickWeight(cos_d) * p.sheen);
}

// GTR1 (Berry) distribution of the clearcoat (Burley 2012, addendum B.1, eq. 4), a < 1 always here.
template <typename T>
T Gtr1D(const T& cos_h, const T& a) {
  using std::log;
  const T a2 = a * a;
  return (a2 - T(1)) / (T(kPi) * log(a2) * (T(1) + (a2 - T(1)) * cos_h * cos_h));
}

// Isotropic Smith GGX G1 with the 1/(2 cos) folded in (BRDF Explorer smithG_GGX).
template <typename T>
T SmithGgxG1(const T& cos_w, const T& alpha) {
  using std::sqrt;
  const T a2 = alpha * alpha;
  const T c2 = cos_w * cos_w;
  return T(1) / (cos_w + sqrt(a2 + c2 - a2 * c2));
}

// Clearcoat lobe (Burley 2012, section 5.6): 0.25 clearcoat Gr Fr Dr, fixed ior 1.5 (F0 = 0.04),
// Smith alpha 0.25.
template <typename T>
T ClearcoatLobe(const PrincipledParams<T>& p, const T& cos_l, const T& cos_v, const T& cos_h, const T& cos_d) {
  const T dr = Gtr1D(cos_h, Mix(T(0.1), T(0.001), p.clearcoat_gloss));
  const T fr = Mix(T(0.04), T(1), SchlickWeight(cos_d));
  const T gr = SmithGgxG1(cos_l, T(0.25)) * SmithGgxG1(cos_v, T(0.25));
  return T(0.25) * p.clearcoat * gr * fr * dr;
}

}  // namespace brdf

namespace brdf {

// What every lobe needs of the directions, before any colour enters: computed once for
// EvaluatePrincipled and EvaluatePrincipledColourParts, so the two cannot disagree.
template <typename T>
struct LobeGeometry {
  T cos_l, cos_v, cos_h, cos_d;  // with the normal (z) and, cos_d, between L and the half vector
  T diffuse_weight;              // diffuse (mixed with subsurface) per unit base colour, 1/sr
  T specular;                    // G D of the specular lobe, 1/sr per unit Fresnel reflectance
};

// False (and `g` untouched) when either direction is at or below the horizon: every lobe is 0.
template <typename T>
bool EvaluateLobeGeometry(const PrincipledParams<T>& p, const Vec3<T>& l, const Vec3<T>& v, LobeGeometry<T>* g) {
  using std::sqrt;
  const T cos_l = l(2);
  const T cos_v = v(2);
  if (!(cos_l > T(0)) || !(cos_v > T(0))) return false;

  Vec3<T> h = l + v;
  T h_len = sqrt(h.squaredNorm());
  if (h_len < T(kTinyLength)) h_len = T(kTinyLength);
  h /= h_len;
  g->cos_l = cos_l;
  g->cos_v = cos_v;
  g->cos_h = h(2);
  g->cos_d = l.dot(h);

  // Diffuse and subsurface, mixed, then (by the caller) scaled by C / pi. Fabric fits and renders
  // have no subsurface and no clearcoat: those lobes are skipped when their weights are exactly 0
  // (IsExactlyZero), about a third of the evaluation.
  const T fd = DisneyDiffuse(cos_l, cos_v, g->cos_d, p.roughness);
  g->diffuse_weight =
      (IsExactlyZero(p.subsurface) ? fd : Mix(fd, DisneySubsurface(cos_l, cos_v, g->cos_d, p.roughness), p.subsurface)) /
      T(kPi);

  T alpha_x, alpha_y;
  AnisotropicAlphas(p.roughness, p.anisotropic, &alpha_x, &alpha_y);
  const T d = Gtr2AnisotropicD(h, alpha_x, alpha_y);
  const T g1 = SmithGgxAnisotropicG1(l, alpha_x, alpha_y) * SmithGgxAnisotropicG1(v, alpha_x, alpha_y);
  g->specular = g1 * d;
  return true;
}

}  // namespace brdf

// The whole BRDF f(L, V) in 1/sr, linear RGB. L and V unit vectors in the local frame (z = normal).
// Zero when either direction is at or below the horizon.
template <typename T>
Vec3<T> EvaluatePrincipled(const PrincipledParams<T>& p, const Vec3<T>& l, const Vec3<T>& v) {
  brdf::LobeGeometry<T> g;
  if (!brdf::EvaluateLobeGeometry(p, l, v, &g)) return Vec3<T>::Zero();
  // Sheen adds on top of the diffuse (both dielectric only).
  const Vec3<T> dielectric = p.base_color * g.diffuse_weight + brdf::SheenLobe(p, g.cos_d);
  const Vec3<T> f = brdf::SchlickFresnel(brdf::SpecularF0(p), g.cos_d);

  const Vec3<T> lobes = dielectric * (T(1) - p.metallic) + f * g.specular;
  if (brdf::IsExactlyZero(p.clearcoat)) return lobes;
  return lobes + Vec3<T>::Constant(brdf::ClearcoatLobe(p, g.cos_l, g.cos_v, g.cos_h, g.cos_d));
}

// The BRDF as three scalars per direction pair, for every base colour at once (p.base_color is
// not read): f(C) = C per_colour + TintColor(C) per_tint + white, in 1/sr. Each lobe is linear in
// C, in its tint or in white (diffuse and metal Fresnel in C; sheen and dielectric Fresnel in the
// tint as far as sheen_tint and specular_tint say, in white for the rest; Fresnel's grazing part
// and clearcoat in white). The fitter solves the base colour in closed form with these, evaluating
// the lobes once per observation instead of once per pass of its luminance iteration.
template <typename T>
struct PrincipledColourParts {
  T per_colour = T(0), per_tint = T(0), white = T(0);
};

template <typename T>
PrincipledColourParts<T> EvaluatePrincipledColourParts(const PrincipledParams<T>& p, const Vec3<T>& l, const Vec3<T>& v) {
  PrincipledColourParts<T> parts;
  brdf::LobeGeometry<T> g;
  if (!brdf::EvaluateLobeGeometry(p, l, v, &g)) return parts;
  const T grazing = brdf::SchlickWeight(g.cos_d);  // Fresnel's and sheen's
  const T dielectric = T(1) - p.metallic;
  const T sheen = p.sheen * grazing * dielectric;
  // The dielectric F0 (0.08 specular, white or tinted) through Fresnel's (1 - grazing) and G D.
  const T dielectric_specular = T(0.08) * p.specular * (T(1) - grazing) * g.specular * dielectric;
  parts.per_colour = g.diffuse_weight * dielectric + p.metallic * (T(1) - grazing) * g.specular;
  parts.per_tint = sheen * p.sheen_tint + dielectric_specular * p.specular_tint;
  parts.white = sheen * (T(1) - p.sheen_tint) + dielectric_specular * (T(1) - p.specular_tint) + grazing * g.specular;
  if (!brdf::IsExactlyZero(p.clearcoat)) parts.white += brdf::ClearcoatLobe(p, g.cos_l, g.cos_v, g.cos_h, g.cos_d);
  return parts;
}

}  // namespace u3mscan

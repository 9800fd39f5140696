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

// The whole BRDF f(L, V) in 1/sr, linear RGB. L and V unit vectors in the local frame (z = normal).
// Zero when either direction is at or below the horizon.
template <typename T>
Vec3<T> EvaluatePrincipled(const PrincipledParams<T>& p, const Vec3<T>& l, const Vec3<T>& v) {
  using std::sqrt;
  const T cos_l = l(2);
  const T cos_v = v(2);
  if (!(cos_l > T(0)) || !(cos_v > T(0))) return Vec3<T>::Zero();

  Vec3<T> h = l + v;
  T h_len = sqrt(h.squaredNorm());
  if (h_len < T(brdf::kTinyLength)) h_len = T(brdf::kTinyLength);
  h /= h_len;
  const T cos_h = h(2);
  const T cos_d = l.dot(h);

  // Diffuse and subsurface, mixed, then scaled by C / pi; sheen adds on top (both dielectric only).
  // Fabric fits and renders have no subsurface and no clearcoat: those lobes are skipped when
  // their weights are exactly 0 (IsExactlyZero), about a third of the evaluation.
  const T fd = brdf::DisneyDiffuse(cos_l, cos_v, cos_d, p.roughness);
  const T diffuse_weight =
      (brdf::IsExactlyZero(p.subsurface) ? fd
                                         : brdf::Mix(fd, brdf::DisneySubsurface(cos_l, cos_v, cos_d, p.roughness), p.subsurface)) /
      T(brdf::kPi);
  const Vec3<T> dielectric = p.base_color * diffuse_weight + brdf::SheenLobe(p, cos_d);

  T alpha_x, alpha_y;
  brdf::AnisotropicAlphas(p.roughness, p.anisotropic, &alpha_x, &alpha_y);
  const T d = brdf::Gtr2AnisotropicD(h, alpha_x, alpha_y);
  const T g = brdf::SmithGgxAnisotropicG1(l, alpha_x, alpha_y) * brdf::SmithGgxAnisotropicG1(v, alpha_x, alpha_y);
  const Vec3<T> f = brdf::SchlickFresnel(brdf::SpecularF0(p), cos_d);

  const Vec3<T> lobes = dielectric * (T(1) - p.metallic) + f * (g * d);
  if (brdf::IsExactlyZero(p.clearcoat)) return lobes;
  return lobes + Vec3<T>::Constant(brdf::ClearcoatLobe(p, cos_l, cos_v, cos_h, cos_d));
}

}  // namespace u3mscan

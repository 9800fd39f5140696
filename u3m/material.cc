#include "u3m/material.h"

#include <chrono>
#include <cmath>
#include <cctype>
#include <cstdio>
#include <random>

#include "core/error.h"

namespace u3mscan {

std::string_view SchemaVersionName(SchemaVersion version) { return version == SchemaVersion::k1_0 ? "1.0" : "1.1"; }

std::string_view RepeatModeName(RepeatMode mode) {
  switch (mode) {
    case RepeatMode::kNormal: return "normal";
    case RepeatMode::kMirrorX: return "mirror_x";
    case RepeatMode::kMirrorY: return "mirror_y";
    case RepeatMode::kMirrorXY: return "mirror_xy";
  }
  return "normal";
}

std::string_view BlendModeName(BlendMode mode) {
  switch (mode) {
    case BlendMode::kAdd: return "add";
    case BlendMode::kSubtract: return "subtract";
    case BlendMode::kMultiply: return "multiply";
    case BlendMode::kDivide: return "divide";
    case BlendMode::kMax: return "max";
    case BlendMode::kMin: return "min";
    case BlendMode::kOverlay: return "overlay";
  }
  return "multiply";
}

const std::vector<ScalarKey>& ScalarKeys() {
  static const std::vector<ScalarKey> keys = {
      {"alpha", &Visualization::alpha, 1.0, true},
      {"anisotropy_value", &Visualization::anisotropy_value, 0.0, false},
      {"anisotropy_rotation", &Visualization::anisotropy_rotation, 0.0, false},  // wraps instead
      {"clearcoat_value", &Visualization::clearcoat_value, 0.0, false},
      {"clearcoat_roughness", &Visualization::clearcoat_roughness, 0.0, false},
      {"ior", &Visualization::ior, 1.4, false},
      {"metalness", &Visualization::metalness, 0.0, true},
      {"displacement", &Visualization::displacement, 0.0, false},
      {"roughness", &Visualization::roughness, 0.7, false},
      {"sheen_value", &Visualization::sheen_value, 0.0, false},
      {"sheen_tint", &Visualization::sheen_tint, 0.0, false},
      {"specular_value", &Visualization::specular_value, 0.5, false},
      {"specular_tint", &Visualization::specular_tint, 0.0, false},
      {"subsurface_radius", &Visualization::subsurface_radius, 0.0, false},
      {"subsurface_value", &Visualization::subsurface_value, 0.0, false},
      {"transmission", &Visualization::transmission, 0.0, true},
  };
  return keys;
}

const std::vector<ColorKey>& ColorKeys() {
  static const std::vector<ColorKey> keys = {
      {"basecolor", &Visualization::basecolor, Rgb3{1.0, 1.0, 1.0}},
      {"subsurface_color", &Visualization::subsurface_color, Rgb3{0.0, 0.0, 0.0}},
  };
  return keys;
}

const std::vector<NormalKey>& NormalKeys() {
  static const std::vector<NormalKey> keys = {
      {"clearcoat_normal", &Visualization::clearcoat_normal},
      {"normal", &Visualization::normal},
  };
  return keys;
}

std::string NewUuid4() {
  static thread_local std::mt19937_64 engine{std::random_device{}()};
  std::uint64_t hi = engine(), lo = engine();
  hi = (hi & 0xFFFFFFFFFFFF0FFFull) | 0x0000000000004000ull;  // version 4
  lo = (lo & 0x3FFFFFFFFFFFFFFFull) | 0x8000000000000000ull;  // variant 10xx
  char text[37];
  std::snprintf(text, sizeof(text), "%08x-%04x-%04x-%04x-%012llx", static_cast<unsigned>(hi >> 32),
                static_cast<unsigned>((hi >> 16) & 0xFFFF), static_cast<unsigned>(hi & 0xFFFF),
                static_cast<unsigned>(lo >> 48), static_cast<unsigned long long>(lo & 0xFFFFFFFFFFFFull));
  return text;
}

bool IsUuid4(std::string_view id) {
  if (id.size() != 36) return false;
  for (std::size_t i = 0; i < id.size(); ++i) {
    const char c = id[i];
    if (i == 8 || i == 13 || i == 18 || i == 23) {
      if (c != '-') return false;
    } else if (!std::isxdigit(static_cast<unsigned char>(c))) {
      return false;
    }
  }
  const char variant = static_cast<char>(std::tolower(static_cast<unsigned char>(id[19])));
  return id[14] == '4' && (variant == '8' || variant == '9' || variant == 'a' || variant == 'b');
}

std::int64_t NowUtcMs() {
  using namespace std::chrono;
  return duration_cast<milliseconds>(system_clock::now().time_since_epoch()).count();
}

std::vector<TextureRef> TextureImages(Visualization& side) {
  std::vector<TextureRef> refs;
  for (const ScalarKey& key : ScalarKeys())
    if (auto& t = (side.*key.member).texture) refs.push_back({key.name, TextureKind::kScalar, &t->image});
  for (const NormalKey& key : NormalKeys())
    if (auto& t = (side.*key.member).texture) refs.push_back({key.name, TextureKind::kNormal, &t->image});
  for (const ColorKey& key : ColorKeys())
    if (auto& t = (side.*key.member).texture) refs.push_back({key.name, TextureKind::kColor, &t->image});
  return refs;
}

std::vector<std::pair<std::string_view, Visualization*>> Sides(Material& material) {
  std::vector<std::pair<std::string_view, Visualization*>> sides;
  if (material.front) sides.emplace_back("front", &*material.front);
  if (material.back) sides.emplace_back("back", &*material.back);
  if (material.side) sides.emplace_back("side", &*material.side);
  return sides;
}

std::vector<std::pair<std::string_view, const Visualization*>> Sides(const Material& material) {
  std::vector<std::pair<std::string_view, const Visualization*>> sides;
  if (material.front) sides.emplace_back("front", &*material.front);
  if (material.back) sides.emplace_back("back", &*material.back);
  if (material.side) sides.emplace_back("side", &*material.side);
  return sides;
}

namespace {

bool InUnit(double v) { return v >= 0.0 && v <= 1.0; }
bool InUnit(const Rgb3& c) { return InUnit(c.r) && InUnit(c.g) && InUnit(c.b); }

void CheckSide(const Visualization& side, const std::string& at, SchemaVersion version, std::vector<std::string>& out) {
  const bool v10 = version == SchemaVersion::k1_0;
  const std::string vname(SchemaVersionName(version));
  const auto check_image = [&](const std::string& where, double w, double h, double dx, double dy) {
    if (!(w >= 0.0 && h >= 0.0 && dx >= 0.0 && dy >= 0.0))
      out.push_back(where + ": sizes and dpi must not be negative");
    if (v10 && std::abs(dx - dy) > 1e-9 * std::max(1.0, std::abs(dx)))
      out.push_back(where + "/dpi: 1.0 has one dpi for both axes, got x " + std::to_string(dx) + " y " +
                    std::to_string(dy));
  };
  for (const ScalarKey& key : ScalarKeys()) {
    const ScalarParam& p = side.*key.member;
    const std::string where = at + "/" + std::string(key.name);
    if (!v10 && key.unit_range_v11 && p.used && !InUnit(p.constant))
      out.push_back(where + "/constant: " + vname + " needs 0..1, got " + std::to_string(p.constant));
    if (p.texture) {
      const TextureImage& i = p.texture->image;
      check_image(where + "/texture/image", i.width_mm, i.height_mm, i.dpi_x, i.dpi_y);
    }
  }
  for (const ColorKey& key : ColorKeys()) {
    const ColorParam& p = side.*key.member;
    const std::string where = at + "/" + std::string(key.name);
    if (p.used && !InUnit(p.constant)) out.push_back(where + "/constant: colours must be in 0..1");
    if (p.texture) {
      if (!InUnit(p.texture->factor)) out.push_back(where + "/texture/factor: colours must be in 0..1");
      const TextureImage& i = p.texture->image;
      check_image(where + "/texture/image", i.width_mm, i.height_mm, i.dpi_x, i.dpi_y);
    }
  }
  for (const NormalKey& key : NormalKeys()) {
    const NormalParam& p = side.*key.member;
    const std::string where = at + "/" + std::string(key.name);
    // With a texture the constant is only the texture's mean, which a 1.0 reader derives itself.
    if (v10 && p.used && !p.texture && (std::abs(p.constant.x) > 1e-6 || std::abs(p.constant.y) > 1e-6 || p.constant.z <= 0.0))
      out.push_back(where + "/constant: 1.0 has no constant normal vector (only a flat (0,0,1) surface)");
    if (!v10 && (std::abs(p.constant.x) > 1.0 || std::abs(p.constant.y) > 1.0 || std::abs(p.constant.z) > 1.0))
      out.push_back(where + "/constant: components must be in -1..1");
    if (p.texture) {
      const TextureImage& i = p.texture->image;
      check_image(where + "/texture/image", i.width_mm, i.height_mm, i.dpi_x, i.dpi_y);
    }
  }
  if (side.preview) {
    if (v10) out.push_back(at + "/preview: 1.0 has no preview");
    else check_image(at + "/preview", side.preview->width_mm, side.preview->height_mm, side.preview->dpi_x,
                     side.preview->dpi_y);
  }
}

}  // namespace

std::vector<std::string> WhatVersionCannotHold(const Material& material, SchemaVersion version) {
  std::vector<std::string> out;
  const bool v10 = version == SchemaVersion::k1_0;
  if (v10) {
    if (material.side) out.push_back("/material/side: 1.0 has no side");
    if (material.physics) out.push_back("/material/physics: 1.0 has no physics");
    if (!material.metadata.is_null()) out.push_back("/material/metadata: 1.0 has no metadata");
  } else if (!material.front && !material.back && !material.side && !material.physics) {
    out.push_back("/material: 1.1 needs at least one of front, back, side, physics");
  }
  if (material.physics) {
    const Physics& p = *material.physics;
    if ((p.thickness_mm && *p.thickness_mm < 0.0) || (p.weight_g_per_m2 && *p.weight_g_per_m2 < 0.0))
      out.push_back("/material/physics: thickness and weight must not be negative");
  }
  for (const auto& [name, side] : Sides(material)) CheckSide(*side, "/material/" + std::string(name), version, out);
  return out;
}

SchemaVersion LowestVersionFor(const Material& material, const std::string& file) {
  const auto v10 = WhatVersionCannotHold(material, SchemaVersion::k1_0);
  if (v10.empty()) return SchemaVersion::k1_0;
  const auto v11 = WhatVersionCannotHold(material, SchemaVersion::k1_1);
  if (v11.empty()) return SchemaVersion::k1_1;
  std::string reasons;
  for (const std::string& r : v11) reasons += (reasons.empty() ? "" : "; ") + r;
  throw InputError(file, "/material", "expected content that U3M 1.0 or 1.1 can hold; 1.1 cannot hold: " + reasons);
}

}  // namespace u3mscan

#pragma once
// The U3M material model, one in-memory form for both schema versions (docs/u3m.md).
//
// Version-neutral units, converted only when a file is read or written:
//   image sizes in millimetres (1.0 files store centimetres, 1.1 files millimetres),
//   resolution as dpi_x/dpi_y (1.0: one number, 1.1: {x, y}),
//   anisotropy rotation in degrees (1.0: degrees, 1.1: fraction of a full turn),
//   normals as vectors {x, y, z} (1.0 has a scalar placeholder that the specification leaves unused).
// Colour constants and factors are linear RGB in 0..1 ("u3m standard colorspace"); colour texture
// files are sRGB-encoded. Timestamps are UTC milliseconds since 1970.

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "u3m/json_value.h"

namespace u3mscan {

enum class SchemaVersion { k1_0, k1_1 };
std::string_view SchemaVersionName(SchemaVersion version);  // "1.0", "1.1"

enum class RepeatMode { kNormal, kMirrorX, kMirrorY, kMirrorXY };
enum class BlendMode { kAdd, kSubtract, kMultiply, kDivide, kMax, kMin, kOverlay };
std::string_view RepeatModeName(RepeatMode mode);
std::string_view BlendModeName(BlendMode mode);

struct Rgb3 {
  double r = 1.0, g = 1.0, b = 1.0;
  bool operator==(const Rgb3&) const = default;
};

struct Vec3 {
  double x = 0.0, y = 0.0, z = 1.0;
  bool operator==(const Vec3&) const = default;
};

// A texture file and where it sits on the fabric.
struct TextureImage {
  std::string path;  // relative to the .u3m, '/' separators
  double width_mm = 0.0;
  double height_mm = 0.0;
  double dpi_x = 0.0;  // pixels per inch along the width
  double dpi_y = 0.0;
  double repeat_rotation = 0.0;  // as in the file (the schemas give no unit; degrees in practice)
  RepeatMode repeat_mode = RepeatMode::kNormal;
  bool operator==(const TextureImage&) const = default;
};

// Scalar map: value at a pixel = offset + average(channels) * factor.
struct ScalarTexture {
  double factor = 1.0;
  double offset = 0.0;
  TextureImage image;
  bool operator==(const ScalarTexture&) const = default;
};

// texture_and_number. `used == false` is the 1.0 `null` ("parameter not used"); 1.1 cannot say
// that, so a 1.1 writer writes the default constant instead.
struct ScalarParam {
  bool used = true;
  double constant = 0.0;
  std::optional<ScalarTexture> texture;
  bool operator==(const ScalarParam&) const = default;
};

struct ColorTexture {
  BlendMode mode = BlendMode::kMultiply;
  Rgb3 factor;
  TextureImage image;  // sRGB-encoded file
  bool operator==(const ColorTexture&) const = default;
};

struct ColorParam {
  bool used = true;
  Rgb3 constant;
  std::optional<ColorTexture> texture;
  bool operator==(const ColorParam&) const = default;
};

// 1.1 texture_and_normal. In 1.0 the texture's `factor` carries `scale`.
struct NormalTexture {
  double scale = 1.0;  // multiplies x and y before renormalisation
  TextureImage image;  // tangent space, OpenGL (+Y up), encoded (n+1)/2, no colour profile
  bool operator==(const NormalTexture&) const = default;
};

struct NormalParam {
  bool used = true;
  Vec3 constant;
  std::optional<NormalTexture> texture;
  bool operator==(const NormalParam&) const = default;
};

// 1.1 per-side preview picture (no repeat).
struct PreviewImage {
  std::string path;
  double width_mm = 0.0;
  double height_mm = 0.0;
  double dpi_x = 0.0;
  double dpi_y = 0.0;
  bool operator==(const PreviewImage&) const = default;
};

// One side's appearance: every visualization key of the schema. Defaults are the specification's
// (alpha 1, ior 1.4, roughness 0.7, specular 0.5, basecolor white, the rest 0; anisotropy_value 0
// although the 1.0 tables say 1: a material is isotropic unless told otherwise, as in the 1.1 schema).
struct Visualization {
  ScalarParam alpha{true, 1.0, {}};
  ScalarParam anisotropy_value{true, 0.0, {}};
  ScalarParam anisotropy_rotation{true, 0.0, {}};  // degrees; texture factor/offset in degrees too
  ScalarParam clearcoat_value{true, 0.0, {}};
  NormalParam clearcoat_normal;
  ScalarParam clearcoat_roughness{true, 0.0, {}};
  ScalarParam ior{true, 1.4, {}};
  ScalarParam metalness{true, 0.0, {}};
  NormalParam normal;
  ScalarParam displacement{true, 0.0, {}};
  ScalarParam roughness{true, 0.7, {}};
  ScalarParam sheen_value{true, 0.0, {}};
  ScalarParam sheen_tint{true, 0.0, {}};
  ScalarParam specular_value{true, 0.5, {}};
  ScalarParam specular_tint{true, 0.0, {}};
  ScalarParam subsurface_radius{true, 0.0, {}};
  ScalarParam subsurface_value{true, 0.0, {}};
  ScalarParam transmission{true, 0.0, {}};
  ColorParam basecolor{true, Rgb3{1.0, 1.0, 1.0}, {}};
  ColorParam subsurface_color{true, Rgb3{0.0, 0.0, 0.0}, {}};
  std::optional<PreviewImage> preview;  // 1.1 only
  bool operator==(const Visualization&) const = default;
};

// The visualization keys by type, in schema order, for code that treats them alike.
struct ScalarKey {
  std::string_view name;
  ScalarParam Visualization::*member;
  double default_constant;
  bool unit_range_v11;  // 1.1 restricts the constant to 0..1
};
struct ColorKey {
  std::string_view name;
  ColorParam Visualization::*member;
  Rgb3 default_constant;
};
struct NormalKey {
  std::string_view name;
  NormalParam Visualization::*member;
};
const std::vector<ScalarKey>& ScalarKeys();  // 16 keys
const std::vector<ColorKey>& ColorKeys();    // basecolor, subsurface_color
const std::vector<NormalKey>& NormalKeys();  // normal, clearcoat_normal

struct CompositionPart {
  double ratio = 1.0;  // 0..1, all parts sum to 1
  std::string type;    // one of the schema's fibre names ("Cotton", "other", ...)
  std::optional<std::string> name;  // required string when type is "other", else null
  bool operator==(const CompositionPart&) const = default;
};

struct NamedType {
  std::string type;
  std::optional<std::string> name;
  bool operator==(const NamedType&) const = default;
};

// 1.1 `physics`.
struct Physics {
  std::optional<double> thickness_mm;
  std::optional<double> weight_g_per_m2;
  std::string fab_path;  // relative path of the FAB physics file; empty = none ("null" in the file)
  std::optional<std::vector<CompositionPart>> composition;
  std::optional<NamedType> material_type;
  std::optional<NamedType> construction;
  bool operator==(const Physics&) const = default;
};

struct Material {
  std::string id;  // UUID, lowercase, without braces
  std::string name;
  std::string description;
  std::int64_t created_ms = 0;   // UTC, milliseconds since 1970-01-01
  std::int64_t modified_ms = 0;  // UTC
  std::optional<Visualization> front;
  std::optional<Visualization> back;  // absent: use front
  std::optional<Visualization> side;  // 1.1; absent: use front
  std::optional<Physics> physics;     // 1.1
  JsonValue metadata;                 // 1.1: null or an object, kept verbatim
  JsonValue custom;                   // null or an object of vendor sections, kept verbatim
  bool operator==(const Material&) const = default;
};

// The vendor key of our own custom section; only this one is ever changed.
inline constexpr std::string_view kOwnVendorKey = "u3mscan";

// A new random version-4 UUID, lowercase, without braces.
std::string NewUuid4();
// True for a lowercase-or-uppercase 8-4-4-4-12 hex UUID with version nibble 4 and variant 8..b.
bool IsUuid4(std::string_view id);
// Current time, UTC milliseconds.
std::int64_t NowUtcMs();

// Which content of `material` `version` cannot hold (empty = it can hold all of it). Each entry
// names a JSON pointer and the reason, e.g. "/material/physics: 1.0 has no physics".
std::vector<std::string> WhatVersionCannotHold(const Material& material, SchemaVersion version);
// The lowest version that holds everything; throws InputError(file, pointer, ...) when none does.
SchemaVersion LowestVersionFor(const Material& material, const std::string& file);

// Every texture image of one side, in schema order.
enum class TextureKind { kScalar, kColor, kNormal };
struct TextureRef {
  std::string_view key;  // visualization key, e.g. "basecolor"
  TextureKind kind;
  TextureImage* image;
};
std::vector<TextureRef> TextureImages(Visualization& side);
// Sides present, with their key: ("front", &front), ("back", ...), ("side", ...).
std::vector<std::pair<std::string_view, Visualization*>> Sides(Material& material);
std::vector<std::pair<std::string_view, const Visualization*>> Sides(const Material& material);

}  // namespace u3mscan

#include "u3m/material_json.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <tuple>

#include "core/error.h"
#include "u3m/relative_path.h"

namespace u3mscan {
namespace {

// Numbers in the material section beyond this magnitude are refused: no size, dpi or shader value
// comes near it, and it keeps later arithmetic (cm -> mm, degrees -> turns) finite.
constexpr double kMaxMagnitude = 1e9;
constexpr double kDegreesPerTurn = 360.0;
constexpr double kMmPerCmFactor = 10.0;

// Enumerations of the 1.1 schema (definitions/composition_part, material_type, construction).
const std::vector<std::string_view> kFibreTypes = {"unknown", "other", "Abaca", "Acetate", "Acrylic", "Alfa", "Alginate", "Alpaca", "Aluminium", "Angora", "Aramid", "Beaver", "Camelhair", "Cashmere", "Cotton", "Cupro", "Elastane", "Guanaco", "Hardware", "Hemp", "Jute", "Linen", "Llama", "Lycra", "Lyocell", "Meril", "Metallic Fibre", "Metallised Polyester", "Micropolypch", "Modacrylic", "Modal Cotton", "Modal", "Mohair", "Neoprene", "Nylon", "Organic cotton", "Polyacryl", "Polyamid", "Polyester", "Polyethylene", "Polypropylen", "Polytaslan", "Ramie", "Rayon", "Recycled Cotton", "Recycled Polyamide", "Recycled Polyester", "Silk", "Spandex", "Tactel", "Triacetate", "Vicugna", "Vinyl", "Virgin Wool", "Wild Silk", "Wool", "Yack"};
const std::vector<std::string_view> kMaterialTypes = {"unknown", "other", "Artwork", "Elastics", "Knit", "Leather", "Metal", "Seam", "Wood", "Woven"};
const std::vector<std::string_view> kConstructionTypes = {"unknown", "other", "1 x 1 flatknit", "1 x 1 rib", "2 x 2 rib", "4 x 2 rib", "Canvas", "Dobby", "Doubleknit", "Doubleweave", "Engineered", "Fleece", "French terry", "Interlock", "Jacquard", "Mesh", "Oxford", "Pique", "Plain weave", "Polarfleece", "Poplin", "Raschel", "Ripstop", "Satin", "Single jersey", "Spacer", "TafFeta", "Terry loop", "Towel", "Tricot", "Twill - left hand (S)", "Twill - right hand (Z)", "Twill", "Velour", "Waffle"};

bool Contains(const std::vector<std::string_view>& list, std::string_view value) {
  return std::find(list.begin(), list.end(), value) != list.end();
}

std::string Describe(const JsonValue& v) {
  switch (v.type()) {
    case JsonValue::Type::kNull: return "null";
    case JsonValue::Type::kBool: return v.bool_value() ? "true" : "false";
    case JsonValue::Type::kNumber: return "the number " + v.text();
    case JsonValue::Type::kString: {
      std::string s = v.text().size() > 60 ? v.text().substr(0, 60) + "..." : v.text();
      return "the string \"" + s + "\"";
    }
    case JsonValue::Type::kArray: return "an array";
    case JsonValue::Type::kObject: return "an object";
  }
  return "a value";
}

std::string Fmt(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.6g", v);
  return buffer;
}

// ---------------------------------------------------------------------------------------------
// Reader

class Reader {
 public:
  Reader(const std::string& file, std::vector<Issue>& issues) : file_(file), issues_(issues) {}

  SchemaVersion version = SchemaVersion::k1_1;
  bool v10() const { return version == SchemaVersion::k1_0; }
  std::string vname() const { return std::string(SchemaVersionName(version)); }

  void Error(const std::string& pointer, std::string message) {
    issues_.push_back({IssueSeverity::kError, pointer, std::move(message)});
  }
  void Warn(const std::string& pointer, std::string message) {
    issues_.push_back({IssueSeverity::kWarning, pointer, std::move(message)});
  }
  [[noreturn]] void Fail(const std::string& pointer, const std::string& expected, const JsonValue* got = nullptr) {
    throw InputError(file_, pointer, "expected " + expected + (got ? ", got " + Describe(*got) : std::string()));
  }

  const JsonValue& Object(const JsonValue& v, const std::string& p, const char* what) {
    if (!v.is_object()) Fail(p, what, &v);
    return v;
  }

  // Member `key` of `object`; nullptr (and an error issue) when missing.
  const JsonValue* Required(const JsonValue& object, std::string_view key, const std::string& p) {
    const JsonValue* v = object.Find(key);
    if (!v) Error(p + "/" + JsonPointerEscape(key), "required key is missing; the default is used");
    return v;
  }

  void CheckKeys(const JsonValue& object, const std::string& p, std::initializer_list<std::string_view> allowed) {
    for (const auto& [key, value] : object.members())
      if (std::find(allowed.begin(), allowed.end(), key) == allowed.end())
        Error(p + "/" + JsonPointerEscape(key), "key not in the " + vname() + " schema; dropped");
  }

  double Number(const JsonValue& v, const std::string& p) {
    if (!v.is_number()) Fail(p, "a number", &v);
    if (!(std::abs(v.number()) <= kMaxMagnitude)) Fail(p, "a number of magnitude at most 1e9", &v);
    return v.number();
  }
  double NumberOr(const JsonValue& object, std::string_view key, const std::string& p, double fallback) {
    const JsonValue* v = Required(object, key, p);
    return v ? Number(*v, p + "/" + std::string(key)) : fallback;
  }
  std::string String(const JsonValue& v, const std::string& p) {
    if (!v.is_string()) Fail(p, "a string", &v);
    return v.text();
  }
  std::string StringOr(const JsonValue& object, std::string_view key, const std::string& p, std::string fallback) {
    const JsonValue* v = Required(object, key, p);
    return v ? String(*v, p + "/" + std::string(key)) : fallback;
  }

  void CheckUnit(double value, const std::string& p, const char* what) {
    if (value < 0.0 || value > 1.0) Error(p, std::string(what) + " must be in 0..1, got " + Fmt(value));
  }
  void CheckNonNegative(double value, const std::string& p) {
    if (value < 0.0) Error(p, "must not be negative, got " + Fmt(value));
  }

  std::string Path(const JsonValue& v, const std::string& p) {
    const std::string text = String(v, p);
    const RelativePathCheck check = CheckRelativePath(text);
    if (check.unsafe)
      Fail(p, "a relative path inside the material's folder (no absolute path, drive letter or '..'), got \"" + text +
                  "\": " + check.unsafe_reason);
    for (const std::string& repair : check.repairs) Error(p, "path \"" + text + "\" breaks the conventions: " + repair);
    for (const std::string& problem : check.problems)
      Error(p, "path \"" + check.normalized + "\" breaks the conventions: " + problem);
    return check.normalized;
  }

  void Dpi(const JsonValue* v, const std::string& p, double& dpi_x, double& dpi_y) {
    if (!v) return;
    if (v->is_number()) {
      if (!v10()) Error(p, "1.1 expects dpi as {x, y}, got one number (1.0 form); read as both");
      dpi_x = dpi_y = Number(*v, p);
    } else if (v->is_object()) {
      if (v10()) Error(p, "1.0 expects dpi as one number, got {x, y} (1.1 form)");
      CheckKeys(*v, p, {"x", "y"});
      dpi_x = NumberOr(*v, "x", p, 0.0);
      dpi_y = NumberOr(*v, "y", p, dpi_x);
    } else {
      Fail(p, v10() ? "dpi as a number" : "dpi as an object {x, y}", v);
    }
    CheckNonNegative(std::min(dpi_x, dpi_y), p);
  }

  TextureImage Image(const JsonValue& v, const std::string& p) {
    Object(v, p, "an image object {path, width, height, dpi, repeat}");
    CheckKeys(v, p, {"width", "height", "dpi", "path", "repeat"});
    TextureImage image;
    const double to_mm = v10() ? kMmPerCmFactor : 1.0;  // 1.0 sizes are centimetres
    image.width_mm = NumberOr(v, "width", p, 0.0) * to_mm;
    image.height_mm = NumberOr(v, "height", p, 0.0) * to_mm;
    CheckNonNegative(image.width_mm, p + "/width");
    CheckNonNegative(image.height_mm, p + "/height");
    Dpi(Required(v, "dpi", p), p + "/dpi", image.dpi_x, image.dpi_y);
    if (const JsonValue* path = Required(v, "path", p)) image.path = Path(*path, p + "/path");
    else Fail(p + "/path", "the path of the texture file");
    if (const JsonValue* repeat = Required(v, "repeat", p)) {
      const std::string rp = p + "/repeat";
      Object(*repeat, rp, "a repeat object {rotation, mode}");
      CheckKeys(*repeat, rp, {"rotation", "mode"});
      image.repeat_rotation = NumberOr(*repeat, "rotation", rp, 0.0);
      const std::string mode = StringOr(*repeat, "mode", rp, "normal");
      if (mode == "normal") image.repeat_mode = RepeatMode::kNormal;
      else if (mode == "mirror_x") image.repeat_mode = RepeatMode::kMirrorX;
      else if (mode == "mirror_y") image.repeat_mode = RepeatMode::kMirrorY;
      else if (mode == "mirror_xy") image.repeat_mode = RepeatMode::kMirrorXY;
      else Error(rp + "/mode", "expected normal, mirror_x, mirror_y or mirror_xy, got \"" + mode + "\"; read as normal");
    }
    return image;
  }

  PreviewImage Preview(const JsonValue& v, const std::string& p) {
    Object(v, p, "a preview object {path, width, height, dpi} or null");
    CheckKeys(v, p, {"width", "height", "dpi", "path"});
    PreviewImage preview;
    const double to_mm = v10() ? kMmPerCmFactor : 1.0;
    preview.width_mm = NumberOr(v, "width", p, 0.0) * to_mm;
    preview.height_mm = NumberOr(v, "height", p, 0.0) * to_mm;
    CheckNonNegative(preview.width_mm, p + "/width");
    CheckNonNegative(preview.height_mm, p + "/height");
    Dpi(Required(v, "dpi", p), p + "/dpi", preview.dpi_x, preview.dpi_y);
    if (const JsonValue* path = Required(v, "path", p)) preview.path = Path(*path, p + "/path");
    else Fail(p + "/path", "the path of the preview file");
    return preview;
  }

  bool NullParameter(const JsonValue& v, const std::string& p) {
    if (!v.is_null()) return false;
    if (!v10()) Error(p, "1.1 parameters may not be null; read as not used (default value)");
    return true;
  }

  ScalarParam Scalar(const JsonValue& v, const std::string& p, const ScalarKey& key) {
    ScalarParam param;
    param.constant = key.default_constant;
    if (NullParameter(v, p)) {
      param.used = false;
      return param;
    }
    Object(v, p, "a texture_and_number object {constant, texture} or null");
    CheckKeys(v, p, {"constant", "texture"});
    param.constant = NumberOr(v, "constant", p, key.default_constant);
    // 1.1 stores the anisotropy rotation as a fraction of a full turn; the model holds degrees.
    const bool turns = key.name == "anisotropy_rotation" && !v10();
    if (!v10() && (key.unit_range_v11 || turns)) CheckUnit(param.constant, p + "/constant", "the constant");
    if (const JsonValue* texture = Required(v, "texture", p); texture && !texture->is_null()) {
      const std::string tp = p + "/texture";
      Object(*texture, tp, "a texture object {factor, offset, image} or null");
      CheckKeys(*texture, tp, {"factor", "offset", "image"});
      ScalarTexture t;
      t.factor = NumberOr(*texture, "factor", tp, 1.0);
      t.offset = NumberOr(*texture, "offset", tp, 0.0);
      const JsonValue* image = Required(*texture, "image", tp);
      if (!image) Fail(tp + "/image", "an image object");
      t.image = Image(*image, tp + "/image");
      if (turns) {
        t.factor *= kDegreesPerTurn;
        t.offset *= kDegreesPerTurn;
      }
      param.texture = t;
    }
    if (turns) param.constant *= kDegreesPerTurn;
    return param;
  }

  Rgb3 Color(const JsonValue& v, const std::string& p, Rgb3 fallback) {
    Object(v, p, "a colour object {r, g, b}");
    CheckKeys(v, p, {"r", "g", "b"});
    Rgb3 c{NumberOr(v, "r", p, fallback.r), NumberOr(v, "g", p, fallback.g), NumberOr(v, "b", p, fallback.b)};
    // Out of 0..1 no version can hold a colour: clamp (an error issue), so a rewrite stays valid.
    for (auto [value, key] : {std::pair{&c.r, "/r"}, std::pair{&c.g, "/g"}, std::pair{&c.b, "/b"}}) {
      if (*value >= 0.0 && *value <= 1.0) continue;
      Error(p + key, "a colour component must be in 0..1, got " + Fmt(*value) + "; clamped");
      *value = std::clamp(*value, 0.0, 1.0);
    }
    return c;
  }

  ColorParam ColorParameter(const JsonValue& v, const std::string& p, const ColorKey& key) {
    ColorParam param;
    param.constant = key.default_constant;
    if (NullParameter(v, p)) {
      param.used = false;
      return param;
    }
    Object(v, p, "a texture_and_color object {constant, texture} or null");
    CheckKeys(v, p, {"constant", "texture"});
    if (const JsonValue* c = Required(v, "constant", p)) param.constant = Color(*c, p + "/constant", key.default_constant);
    if (const JsonValue* texture = Required(v, "texture", p); texture && !texture->is_null()) {
      const std::string tp = p + "/texture";
      Object(*texture, tp, "a texture object {mode, factor, image} or null");
      CheckKeys(*texture, tp, {"mode", "factor", "image"});
      ColorTexture t;
      const std::string mode = StringOr(*texture, "mode", tp, "multiply");
      static const std::vector<std::pair<std::string_view, BlendMode>> kModes = {
          {"add", BlendMode::kAdd}, {"subtract", BlendMode::kSubtract}, {"multiply", BlendMode::kMultiply},
          {"divide", BlendMode::kDivide}, {"max", BlendMode::kMax}, {"min", BlendMode::kMin},
          {"overlay", BlendMode::kOverlay}};
      const auto it = std::find_if(kModes.begin(), kModes.end(), [&](const auto& m) { return m.first == mode; });
      if (it != kModes.end()) t.mode = it->second;
      else Error(tp + "/mode", "expected add, subtract, multiply, divide, max, min or overlay, got \"" + mode +
                                   "\"; read as multiply");
      if (const JsonValue* f = Required(*texture, "factor", tp)) t.factor = Color(*f, tp + "/factor", Rgb3{});
      const JsonValue* image = Required(*texture, "image", tp);
      if (!image) Fail(tp + "/image", "an image object");
      t.image = Image(*image, tp + "/image");
      param.texture = t;
    }
    return param;
  }

  NormalParam Normal(const JsonValue& v, const std::string& p) {
    NormalParam param;
    if (NullParameter(v, p)) {
      param.used = false;
      return param;
    }
    Object(v, p, "a normal object {constant, texture} or null");
    CheckKeys(v, p, {"constant", "texture"});
    if (const JsonValue* c = Required(v, "constant", p)) {
      const std::string cp = p + "/constant";
      if (c->is_number()) {  // 1.0: a placeholder the specification leaves unused
        if (!v10()) Error(cp, "1.1 expects a vector {x, y, z}, got a number (1.0 form); read as (0, 0, 1)");
        if (Number(*c, cp) != 0.0) Warn(cp, "1.0 does not use the normal constant; " + c->text() + " ignored");
      } else if (c->is_object()) {
        if (v10()) Error(cp, "1.0 expects a number, got a vector {x, y, z} (1.1 form)");
        CheckKeys(*c, cp, {"x", "y", "z"});
        param.constant = Vec3{NumberOr(*c, "x", cp, 0.0), NumberOr(*c, "y", cp, 0.0), NumberOr(*c, "z", cp, 1.0)};
        for (double comp : {param.constant.x, param.constant.y, param.constant.z})
          if (std::abs(comp) > 1.0) Error(cp, "components must be in -1..1, got " + Fmt(comp));
      } else {
        Fail(cp, v10() ? "a number" : "a vector {x, y, z}", c);
      }
    }
    if (const JsonValue* texture = Required(v, "texture", p); texture && !texture->is_null()) {
      const std::string tp = p + "/texture";
      Object(*texture, tp, "a normal texture object or null");
      NormalTexture t;
      const bool form_v10 = texture->Find("factor") && !texture->Find("scale");
      if (form_v10) {
        if (!v10()) Error(tp, "1.1 expects {scale, image}, got {factor, offset, image} (1.0 form); factor read as scale");
        CheckKeys(*texture, tp, {"factor", "offset", "image"});
        t.scale = NumberOr(*texture, "factor", tp, 1.0);
        if (const JsonValue* offset = texture->Find("offset"); offset && Number(*offset, tp + "/offset") != 0.0)
          Warn(tp + "/offset", "normal maps take no offset; " + offset->text() + " ignored");
      } else {
        if (v10()) Error(tp, "1.0 expects {factor, offset, image}, got {scale, image} (1.1 form); scale read as factor");
        CheckKeys(*texture, tp, {"scale", "image"});
        t.scale = NumberOr(*texture, "scale", tp, 1.0);
      }
      const JsonValue* image = Required(*texture, "image", tp);
      if (!image) Fail(tp + "/image", "an image object");
      t.image = Image(*image, tp + "/image");
      param.texture = t;
    }
    return param;
  }

  std::optional<Visualization> Side(const JsonValue& v, const std::string& p) {
    if (v.is_null()) return std::nullopt;
    Object(v, p, "a visualization object or null");
    Visualization side;
    for (const auto& member : v.members()) {
      const std::string& key = member.first;  // a named reference: clang 14 cannot capture a structured binding
      const bool known = key == "shader" || key == "preview" ||
                         std::any_of(ScalarKeys().begin(), ScalarKeys().end(), [&](auto& k) { return k.name == key; }) ||
                         std::any_of(ColorKeys().begin(), ColorKeys().end(), [&](auto& k) { return k.name == key; }) ||
                         std::any_of(NormalKeys().begin(), NormalKeys().end(), [&](auto& k) { return k.name == key; });
      if (!known) Error(p + "/" + JsonPointerEscape(key), "key not in the " + vname() + " schema; dropped");
    }
    for (const ScalarKey& key : ScalarKeys())
      if (const JsonValue* m = Required(v, key.name, p)) side.*key.member = Scalar(*m, p + "/" + std::string(key.name), key);
    for (const NormalKey& key : NormalKeys())
      if (const JsonValue* m = Required(v, key.name, p)) side.*key.member = Normal(*m, p + "/" + std::string(key.name));
    for (const ColorKey& key : ColorKeys())
      if (const JsonValue* m = Required(v, key.name, p))
        side.*key.member = ColorParameter(*m, p + "/" + std::string(key.name), key);
    if (const JsonValue* shader = Required(v, "shader", p)) {
      if (!shader->is_string() || shader->text() != "principled")
        Error(p + "/shader", "expected \"principled\", got " + Describe(*shader));
    }
    const JsonValue* preview = v10() ? v.Find("preview") : Required(v, "preview", p);
    if (preview) {
      if (v10()) Error(p + "/preview", "1.0 has no preview; kept (writing it needs 1.1)");
      if (!preview->is_null()) side.preview = Preview(*preview, p + "/preview");
    }
    // Plausibility: legal values that real exporters get wrong.
    if (side.ior.used && side.ior.constant < 1.0)
      Warn(p + "/ior/constant", "an index of refraction below 1 (" + Fmt(side.ior.constant) +
                                    ") is not physical; renderers may use the default 1.4 instead");
    if (side.metalness.constant == 1.0 && side.sheen_tint.constant == 1.0 && side.specular_tint.constant == 1.0)
      Warn(p + "/metalness/constant", "metalness, sheen_tint and specular_tint are all 1: the known exporter bug "
                                      "that writes 1 for 0; check the material");
    return side;
  }

  NamedType Named(const JsonValue& v, const std::string& p, const std::vector<std::string_view>& types) {
    Object(v, p, "an object {type, name} or null");
    CheckKeys(v, p, {"type", "name"});
    NamedType named;
    named.type = StringOr(v, "type", p, "unknown");
    if (const JsonValue* name = Required(v, "name", p); name && !name->is_null())
      named.name = String(*name, p + "/name");
    NormaliseNamedType(named.type, named.name, types, p);
    return named;
  }

  // The schema's if/then/else: a name exactly when the type is "other". Keeps the information in
  // a form every writer can hold: an unknown type becomes "other" named after it.
  void NormaliseNamedType(std::string& type, std::optional<std::string>& name,
                          const std::vector<std::string_view>& types, const std::string& p) {
    if (!Contains(types, type)) {
      Error(p + "/type", "\"" + type + "\" is not in the schema's list; read as \"other\" with that name");
      name = name ? type + " (" + *name + ")" : type;
      type = "other";
      return;
    }
    if (type == "other" && !name) {
      Error(p + "/name", "type \"other\" needs a name string; read as \"other\"");
      name = "other";
    } else if (type != "other" && name) {
      Error(p + "/name", "must be null unless type is \"other\"; \"" + *name + "\" dropped");
      name.reset();
    }
  }

  std::optional<double> OptionalNumber(const JsonValue& object, std::string_view key, const std::string& p) {
    const JsonValue* v = Required(object, key, p);
    if (!v || v->is_null()) return std::nullopt;
    const double value = Number(*v, p + "/" + std::string(key));
    CheckNonNegative(value, p + "/" + std::string(key));
    return value;
  }

  std::optional<Physics> PhysicsSection(const JsonValue& v, const std::string& p) {
    if (v.is_null()) return std::nullopt;
    Object(v, p, "a physics object or null");
    CheckKeys(v, p, {"thickness", "weight", "devices", "composition", "material_type", "construction"});
    Physics physics;
    physics.thickness_mm = OptionalNumber(v, "thickness", p);
    physics.weight_g_per_m2 = OptionalNumber(v, "weight", p);
    if (const JsonValue* devices = Required(v, "devices", p)) {
      const std::string dp = p + "/devices";
      Object(*devices, dp, "a devices object {fab}");
      CheckKeys(*devices, dp, {"fab"});
      if (const JsonValue* fab = Required(*devices, "fab", dp)) {
        if (fab->is_null()) Error(dp + "/fab", "\"no FAB file\" is the string \"null\", got null");
        else if (String(*fab, dp + "/fab") != "null") physics.fab_path = Path(*fab, dp + "/fab");
      }
    }
    if (const JsonValue* composition = Required(v, "composition", p); composition && !composition->is_null()) {
      const std::string cp = p + "/composition";
      Object(*composition, cp, "a composition object {parts} or null");
      CheckKeys(*composition, cp, {"parts"});
      std::vector<CompositionPart> parts;
      if (const JsonValue* list = Required(*composition, "parts", cp)) {
        if (!list->is_array()) Fail(cp + "/parts", "an array", list);
        if (list->items().empty()) Error(cp + "/parts", "needs at least one part");
        double sum = 0.0;
        for (std::size_t i = 0; i < list->items().size(); ++i) {
          const std::string pp = cp + "/parts/" + std::to_string(i);
          const JsonValue& item = list->items()[i];
          Object(item, pp, "a composition part {ratio, type, name}");
          CheckKeys(item, pp, {"ratio", "type", "name"});
          CompositionPart part;
          part.ratio = NumberOr(item, "ratio", pp, 0.0);
          if (part.ratio < 0.0 || part.ratio > 1.0) {
            Error(pp + "/ratio", "a ratio must be in 0..1, got " + Fmt(part.ratio) + "; clamped");
            part.ratio = std::clamp(part.ratio, 0.0, 1.0);
          }
          sum += part.ratio;
          part.type = StringOr(item, "type", pp, "unknown");
          if (const JsonValue* name = Required(item, "name", pp); name && !name->is_null())
            part.name = String(*name, pp + "/name");
          NormaliseNamedType(part.type, part.name, kFibreTypes, pp);
          parts.push_back(std::move(part));
        }
        if (!list->items().empty() && std::abs(sum - 1.0) > 1e-3)
          Warn(cp + "/parts", "ratios should sum up to 1, got " + Fmt(sum));
      }
      physics.composition = std::move(parts);
    }
    if (const JsonValue* t = Required(v, "material_type", p); t && !t->is_null())
      physics.material_type = Named(*t, p + "/material_type", kMaterialTypes);
    if (const JsonValue* t = Required(v, "construction", p); t && !t->is_null())
      physics.construction = Named(*t, p + "/construction", kConstructionTypes);
    return physics;
  }

  std::int64_t Timestamp(const JsonValue* v, const std::string& p) {
    if (!v) return 0;
    const std::string text = String(*v, p);
    const std::optional<ParsedTimestamp> t = ParseTimestamp(text);
    if (!t) Fail(p, "an RFC 3339 date-time such as 2024-05-01T12:00:00Z", v);
    if (!t->has_zone) Error(p, "\"" + text + "\" has no time zone (not a valid date-time); read as UTC");
    if (t->space_separator) Error(p, "\"" + text + "\" separates date and time with a space, not 'T'");
    if (t->has_offset) Warn(p, "\"" + text + "\" has a UTC offset: valid, but some readers reject it; written as UTC");
    return t->utc_ms;
  }

  std::string Id(const JsonValue* v, const std::string& p) {
    if (!v) return {};
    std::string id = String(*v, p);
    std::string core = id;
    const bool braces = core.size() >= 2 && core.front() == '{' && core.back() == '}';
    if (braces) core = core.substr(1, core.size() - 2);
    bool hex_uuid = core.size() == 36;
    for (std::size_t i = 0; hex_uuid && i < core.size(); ++i)
      hex_uuid = (i == 8 || i == 13 || i == 18 || i == 23) ? core[i] == '-' : std::isxdigit(static_cast<unsigned char>(core[i])) != 0;
    if (!hex_uuid) {
      Error(p, "\"" + id + "\" is not a UUID; a writer gives the material a new id");
      return id;
    }
    std::string lower = core;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
    if (!IsUuid4(lower)) {
      if (v10()) Warn(p, "\"" + id + "\" is not a version-4 UUID; a writer gives the material a new id");
      else Error(p, "\"" + id + "\" is not a version-4 UUID; a writer gives the material a new id");
    }
    if (braces) Warn(p, "braces around the id: allowed, but written without");
    if (lower != core) Warn(p, "uppercase hex digits in the id: written lowercase");
    return lower;
  }

  const std::string& file() const { return file_; }

 private:
  const std::string& file_;
  std::vector<Issue>& issues_;
};

// ---------------------------------------------------------------------------------------------
// Writer

class Writer {
 public:
  Writer(const std::string& file, SchemaVersion version, std::vector<Issue>& notes)
      : file_(file), version_(version), notes_(notes) {}

  bool v10() const { return version_ == SchemaVersion::k1_0; }

  // Every number of the material goes through here: what the reader refuses (not finite, beyond
  // kMaxMagnitude) is refused before it is written, so a written file always reads back. A value
  // read within the bound can leave it on conversion: a 1.1 rotation of 4e8 turns is 1.4e11
  // degrees in 1.0 (found by fuzz_u3m_json).
  JsonValue Num(double value, const std::string& p) const {
    if (!std::isfinite(value)) throw InputError(file_, p, "expected a finite number");
    if (std::abs(value) > kMaxMagnitude) {
      throw InputError(file_, p, "expected a number of magnitude at most 1e9 (what a reader accepts), got " + Fmt(value));
    }
    return JsonValue::Number(value);
  }

  JsonValue PathValue(const std::string& path, const std::string& p) const {
    std::string why;
    if (!IsWritableRelativePath(path, &why))
      throw InputError(file_, p, "expected a relative '/' path that the conventions allow (" + why + "), got \"" + path + "\"");
    return JsonValue::String(path);
  }

  JsonValue Dpi(double x, double y, const std::string& p) const {
    if (v10()) return Num(x, p);
    JsonValue dpi = JsonValue::Object();
    dpi.Set("x", Num(x, p + "/x"));
    dpi.Set("y", Num(y, p + "/y"));
    return dpi;
  }

  JsonValue Image(const TextureImage& image, const std::string& p) const {
    const double from_mm = v10() ? 1.0 / kMmPerCmFactor : 1.0;
    JsonValue v = JsonValue::Object();
    v.Set("path", PathValue(image.path, p + "/path"));
    v.Set("width", Num(image.width_mm * from_mm, p + "/width"));
    v.Set("height", Num(image.height_mm * from_mm, p + "/height"));
    v.Set("dpi", Dpi(image.dpi_x, image.dpi_y, p + "/dpi"));
    JsonValue repeat = JsonValue::Object();
    repeat.Set("rotation", Num(image.repeat_rotation, p + "/repeat/rotation"));
    repeat.Set("mode", JsonValue::String(std::string(RepeatModeName(image.repeat_mode))));
    v.Set("repeat", std::move(repeat));
    return v;
  }

  JsonValue Color(const Rgb3& c, const std::string& p) const {
    JsonValue v = JsonValue::Object();
    v.Set("r", Num(c.r, p + "/r"));
    v.Set("g", Num(c.g, p + "/g"));
    v.Set("b", Num(c.b, p + "/b"));
    return v;
  }

  void NoteNullRule(const std::string& p) {
    notes_.push_back({IssueSeverity::kWarning, p, "1.1 has no null parameter: the unused parameter is written as its default"});
  }

  JsonValue Scalar(const ScalarParam& param, const ScalarKey& key, const std::string& p) {
    if (!param.used && v10()) return JsonValue::Null();
    if (!param.used) NoteNullRule(p);
    const bool turns = key.name == "anisotropy_rotation" && !v10();
    double constant = param.used ? param.constant : key.default_constant;
    if (turns) {  // a rotation is periodic: wrap into one turn so that 1.1's 0..1 holds it
      constant = std::fmod(constant, kDegreesPerTurn);
      if (constant < 0.0) constant += kDegreesPerTurn;
      constant /= kDegreesPerTurn;
      if (constant >= 1.0) constant = 0.0;
    }
    JsonValue v = JsonValue::Object();
    v.Set("constant", Num(constant, p + "/constant"));
    if (param.used && param.texture) {
      const double scale = turns ? 1.0 / kDegreesPerTurn : 1.0;
      JsonValue t = JsonValue::Object();
      t.Set("factor", Num(param.texture->factor * scale, p + "/texture/factor"));
      t.Set("offset", Num(param.texture->offset * scale, p + "/texture/offset"));
      t.Set("image", Image(param.texture->image, p + "/texture/image"));
      v.Set("texture", std::move(t));
    } else {
      v.Set("texture", JsonValue::Null());
    }
    return v;
  }

  JsonValue ColorParameter(const ColorParam& param, const ColorKey& key, const std::string& p) {
    if (!param.used && v10()) return JsonValue::Null();
    if (!param.used) NoteNullRule(p);
    JsonValue v = JsonValue::Object();
    v.Set("constant", Color(param.used ? param.constant : key.default_constant, p + "/constant"));
    if (param.used && param.texture) {
      JsonValue t = JsonValue::Object();
      t.Set("mode", JsonValue::String(std::string(BlendModeName(param.texture->mode))));
      t.Set("factor", Color(param.texture->factor, p + "/texture/factor"));
      t.Set("image", Image(param.texture->image, p + "/texture/image"));
      v.Set("texture", std::move(t));
    } else {
      v.Set("texture", JsonValue::Null());
    }
    return v;
  }

  JsonValue Normal(const NormalParam& param, const std::string& p) {
    if (!param.used && v10()) return JsonValue::Null();
    if (!param.used) NoteNullRule(p);
    JsonValue v = JsonValue::Object();
    if (v10()) {
      v.Set("constant", JsonValue::Number(0.0));  // unused by 1.0 readers
    } else {
      const Vec3 c = param.used ? param.constant : Vec3{};
      JsonValue constant = JsonValue::Object();
      constant.Set("x", Num(c.x, p + "/constant/x"));
      constant.Set("y", Num(c.y, p + "/constant/y"));
      constant.Set("z", Num(c.z, p + "/constant/z"));
      v.Set("constant", std::move(constant));
    }
    if (param.used && param.texture) {
      JsonValue t = JsonValue::Object();
      if (v10()) {
        t.Set("factor", Num(param.texture->scale, p + "/texture/factor"));
        t.Set("offset", JsonValue::Number(0.0));
      } else {
        t.Set("scale", Num(param.texture->scale, p + "/texture/scale"));
      }
      t.Set("image", Image(param.texture->image, p + "/texture/image"));
      v.Set("texture", std::move(t));
    } else {
      v.Set("texture", JsonValue::Null());
    }
    return v;
  }

  JsonValue Side(const std::optional<Visualization>& side, const std::string& p) {
    if (!side) return JsonValue::Null();
    // Schema order of the visualisation properties.
    static const std::vector<std::string_view> kOrder = {
        "alpha", "anisotropy_value", "anisotropy_rotation", "clearcoat_value", "clearcoat_normal",
        "clearcoat_roughness", "ior", "metalness", "normal", "displacement", "roughness", "sheen_value",
        "sheen_tint", "specular_value", "specular_tint", "subsurface_radius", "subsurface_value",
        "transmission", "basecolor", "subsurface_color"};
    JsonValue v = JsonValue::Object();
    for (std::string_view name : kOrder) {
      const std::string kp = p + "/" + std::string(name);
      for (const ScalarKey& key : ScalarKeys())
        if (key.name == name) v.Set(std::string(name), Scalar(*side.*key.member, key, kp));
      for (const ColorKey& key : ColorKeys())
        if (key.name == name) v.Set(std::string(name), ColorParameter(*side.*key.member, key, kp));
      for (const NormalKey& key : NormalKeys())
        if (key.name == name) v.Set(std::string(name), Normal(*side.*key.member, kp));
    }
    v.Set("shader", JsonValue::String("principled"));
    if (!v10()) {
      if (side->preview) {
        const PreviewImage& preview = *side->preview;
        JsonValue pv = JsonValue::Object();
        pv.Set("path", PathValue(preview.path, p + "/preview/path"));
        pv.Set("width", Num(preview.width_mm, p + "/preview/width"));
        pv.Set("height", Num(preview.height_mm, p + "/preview/height"));
        pv.Set("dpi", Dpi(preview.dpi_x, preview.dpi_y, p + "/preview/dpi"));
        v.Set("preview", std::move(pv));
      } else {
        v.Set("preview", JsonValue::Null());
      }
    }
    return v;
  }

  static JsonValue Named(const std::optional<NamedType>& named) {
    if (!named) return JsonValue::Null();
    JsonValue v = JsonValue::Object();
    v.Set("type", JsonValue::String(named->type));
    v.Set("name", named->name ? JsonValue::String(*named->name) : JsonValue::Null());
    return v;
  }

  JsonValue PhysicsSection(const std::optional<Physics>& physics, const std::string& p) {
    if (!physics) return JsonValue::Null();
    JsonValue v = JsonValue::Object();
    v.Set("thickness", physics->thickness_mm ? Num(*physics->thickness_mm, p + "/thickness") : JsonValue::Null());
    v.Set("weight", physics->weight_g_per_m2 ? Num(*physics->weight_g_per_m2, p + "/weight") : JsonValue::Null());
    JsonValue devices = JsonValue::Object();
    devices.Set("fab", physics->fab_path.empty() ? JsonValue::String("null") : PathValue(physics->fab_path, p + "/devices/fab"));
    v.Set("devices", std::move(devices));
    if (physics->composition) {
      if (physics->composition->empty())
        throw InputError(file_, p + "/composition/parts", "expected at least one composition part");
      JsonValue parts = JsonValue::Array();
      for (std::size_t i = 0; i < physics->composition->size(); ++i) {
        const CompositionPart& part = (*physics->composition)[i];
        const std::string pp = p + "/composition/parts/" + std::to_string(i);
        if (!Contains(kFibreTypes, part.type))
          throw InputError(file_, pp + "/type", "expected a fibre type of the 1.1 schema, got \"" + part.type + "\"");
        if ((part.type == "other") != part.name.has_value())
          throw InputError(file_, pp + "/name", "expected a name exactly when type is \"other\"");
        if (!(part.ratio >= 0.0 && part.ratio <= 1.0))
          throw InputError(file_, pp + "/ratio", "expected a ratio in 0..1");
        JsonValue item = JsonValue::Object();
        item.Set("ratio", Num(part.ratio, pp + "/ratio"));
        item.Set("type", JsonValue::String(part.type));
        item.Set("name", part.name ? JsonValue::String(*part.name) : JsonValue::Null());
        parts.Push(std::move(item));
      }
      JsonValue composition = JsonValue::Object();
      composition.Set("parts", std::move(parts));
      v.Set("composition", std::move(composition));
    } else {
      v.Set("composition", JsonValue::Null());
    }
    for (const auto& [key, named, list] :
         {std::tuple{"material_type", &physics->material_type, &kMaterialTypes},
          std::tuple{"construction", &physics->construction, &kConstructionTypes}}) {
      if (*named) {
        if (!Contains(*list, (*named)->type))
          throw InputError(file_, p + "/" + key + "/type", "expected a type of the 1.1 schema, got \"" + (*named)->type + "\"");
        if (((*named)->type == "other") != (*named)->name.has_value())
          throw InputError(file_, p + "/" + key + "/name", "expected a name exactly when type is \"other\"");
      }
      v.Set(key, Named(*named));
    }
    return v;
  }

 private:
  const std::string& file_;
  SchemaVersion version_;
  std::vector<Issue>& notes_;
};

int DaysInMonth(int year, int month) {
  static const int kDays[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  const bool leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
  return month == 2 && leap ? 29 : kDays[month - 1];
}

// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's days_from_civil).
std::int64_t DaysFromCivil(std::int64_t y, unsigned m, unsigned d) {
  y -= m <= 2;
  const std::int64_t era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<std::int64_t>(doe) - 719468;
}

void CivilFromDays(std::int64_t z, int& year, int& month, int& day) {
  z += 719468;
  const std::int64_t era = (z >= 0 ? z : z - 146096) / 146097;
  const unsigned doe = static_cast<unsigned>(z - era * 146097);
  const unsigned yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  const unsigned doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const unsigned mp = (5 * doy + 2) / 153;
  day = static_cast<int>(doy - (153 * mp + 2) / 5 + 1);
  month = static_cast<int>(mp < 10 ? mp + 3 : mp - 9);
  year = static_cast<int>(static_cast<std::int64_t>(yoe) + era * 400 + (month <= 2));
}

}  // namespace

std::optional<ParsedTimestamp> ParseTimestamp(std::string_view s) {
  const auto digits = [&](std::size_t pos, std::size_t n, int& out) {
    if (pos + n > s.size()) return false;
    out = 0;
    for (std::size_t i = pos; i < pos + n; ++i) {
      if (!std::isdigit(static_cast<unsigned char>(s[i]))) return false;
      out = out * 10 + (s[i] - '0');
    }
    return true;
  };
  int year, month, day, hour, minute, second;
  if (!digits(0, 4, year) || s.size() < 19 || s[4] != '-' || !digits(5, 2, month) || s[7] != '-' ||
      !digits(8, 2, day) || !digits(11, 2, hour) || s[13] != ':' || !digits(14, 2, minute) || s[16] != ':' ||
      !digits(17, 2, second))
    return std::nullopt;
  ParsedTimestamp t;
  if (s[10] == ' ') t.space_separator = true;
  else if (s[10] != 'T' && s[10] != 't') return std::nullopt;
  if (month < 1 || month > 12 || day < 1 || day > DaysInMonth(year, month) || hour > 23 || minute > 59 || second > 60)
    return std::nullopt;
  std::size_t pos = 19;
  int millis = 0;
  if (pos < s.size() && s[pos] == '.') {
    ++pos;
    int count = 0;
    while (pos < s.size() && std::isdigit(static_cast<unsigned char>(s[pos]))) {
      if (count < 3) millis = millis * 10 + (s[pos] - '0');
      ++count;
      ++pos;
    }
    if (count == 0) return std::nullopt;
    for (int i = count; i < 3; ++i) millis *= 10;
  }
  int offset_minutes = 0;
  if (pos < s.size()) {
    if (s[pos] == 'Z' || s[pos] == 'z') {
      t.has_zone = true;
      ++pos;
    } else if (s[pos] == '+' || s[pos] == '-') {
      int oh, om;
      if (!digits(pos + 1, 2, oh) || pos + 3 >= s.size() || s[pos + 3] != ':' || !digits(pos + 4, 2, om) || oh > 23 ||
          om > 59)
        return std::nullopt;
      offset_minutes = (s[pos] == '-' ? -1 : 1) * (oh * 60 + om);
      t.has_zone = true;
      t.has_offset = offset_minutes != 0 || s[pos] == '-';
      pos += 6;
    }
  }
  if (pos != s.size()) return std::nullopt;
  if (second == 60) second = 59;  // a leap second: no std::chrono time point holds it
  const std::int64_t days = DaysFromCivil(year, static_cast<unsigned>(month), static_cast<unsigned>(day));
  const std::int64_t seconds = days * 86400 + hour * 3600 + minute * 60 + second - offset_minutes * 60;
  t.utc_ms = seconds * 1000 + millis;
  return t;
}

std::string FormatUtcTimestamp(std::int64_t utc_ms) {
  std::int64_t seconds = utc_ms / 1000;
  int millis = static_cast<int>(utc_ms % 1000);
  if (millis < 0) {
    millis += 1000;
    seconds -= 1;
  }
  std::int64_t days = seconds / 86400;
  std::int64_t rest = seconds % 86400;
  if (rest < 0) {
    rest += 86400;
    days -= 1;
  }
  int year, month, day;
  CivilFromDays(days, year, month, day);
  char buffer[40];
  if (millis != 0)
    std::snprintf(buffer, sizeof(buffer), "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", year, month, day,
                  static_cast<int>(rest / 3600), static_cast<int>(rest / 60 % 60), static_cast<int>(rest % 60), millis);
  else
    std::snprintf(buffer, sizeof(buffer), "%04d-%02d-%02dT%02d:%02d:%02dZ", year, month, day,
                  static_cast<int>(rest / 3600), static_cast<int>(rest / 60 % 60), static_cast<int>(rest % 60));
  return buffer;
}

MaterialReadResult ReadMaterialJson(std::string_view text, const std::string& file) {
  MaterialReadResult result;
  const JsonValue root = ParseJson(text, file);
  Reader r(file, result.issues);
  r.Object(root, "", "a U3M object {schema, material, custom}");

  const JsonValue* schema = root.Find("schema");
  if (!schema) throw InputError(file, "/schema", "expected the schema version \"1.0\" or \"1.1\", got no \"schema\" key");
  if (!schema->is_string() || (schema->text() != "1.0" && schema->text() != "1.1"))
    r.Fail("/schema", "the schema version \"1.0\" or \"1.1\"", schema);
  result.version = schema->text() == "1.0" ? SchemaVersion::k1_0 : SchemaVersion::k1_1;
  r.version = result.version;
  r.CheckKeys(root, "", {"schema", "material", "custom"});

  const JsonValue* material = root.Find("material");
  if (!material) throw InputError(file, "/material", "expected a material object, got no \"material\" key");
  const std::string mp = "/material";
  r.Object(*material, mp, "a material object");
  const bool v10 = r.v10();
  for (const auto& [key, value] : material->members()) {
    static const std::vector<std::string_view> kCommon = {"id", "name", "description", "created", "modified", "front", "back"};
    static const std::vector<std::string_view> kNew = {"side", "physics", "metadata"};
    if (Contains(kCommon, key)) continue;
    if (Contains(kNew, key)) {
      if (v10) r.Error(mp + "/" + key, "1.0 has no " + key + "; kept (writing it needs 1.1)");
      continue;
    }
    r.Error(mp + "/" + JsonPointerEscape(key), "key not in the " + r.vname() + " schema; dropped");
  }

  Material& m = result.material;
  m.id = r.Id(r.Required(*material, "id", mp), mp + "/id");
  m.name = r.StringOr(*material, "name", mp, "");
  if (m.name.empty()) r.Error(mp + "/name", "the name must not be empty");
  m.description = r.StringOr(*material, "description", mp, "");
  m.created_ms = r.Timestamp(r.Required(*material, "created", mp), mp + "/created");
  m.modified_ms = r.Timestamp(r.Required(*material, "modified", mp), mp + "/modified");
  if (const JsonValue* v = r.Required(*material, "front", mp)) m.front = r.Side(*v, mp + "/front");
  if (const JsonValue* v = r.Required(*material, "back", mp)) m.back = r.Side(*v, mp + "/back");
  const auto newer = [&](std::string_view key) { return v10 ? material->Find(key) : r.Required(*material, key, mp); };
  if (const JsonValue* v = newer("side")) m.side = r.Side(*v, mp + "/side");
  if (const JsonValue* v = newer("physics")) m.physics = r.PhysicsSection(*v, mp + "/physics");
  if (const JsonValue* v = newer("metadata")) {
    if (!v->is_null() && !v->is_object()) r.Fail(mp + "/metadata", "an object or null", v);
    m.metadata = *v;
  }
  if (!v10 && !m.front && !m.back && !m.side && !m.physics)
    r.Error(mp, "1.1 needs at least one of front, back, side, physics to be non-null");

  if (const JsonValue* custom = r.Required(root, "custom", "")) {
    if (!custom->is_null() && !custom->is_object()) r.Fail("/custom", "an object or null", custom);
    m.custom = *custom;
  }
  return result;
}

MaterialWriteResult WriteMaterialJson(const Material& material, const MaterialWriteOptions& options,
                                      const std::string& file) {
  MaterialWriteResult result;
  if (options.version) {
    const std::vector<std::string> missing = WhatVersionCannotHold(material, *options.version);
    if (!missing.empty()) {
      std::string reasons;
      for (const std::string& reason : missing) reasons += (reasons.empty() ? "" : "; ") + reason;
      throw InputError(file, "/schema",
                       "expected content that U3M " + std::string(SchemaVersionName(*options.version)) +
                           " can hold, but it cannot hold: " + reasons);
    }
    result.version = *options.version;
  } else {
    result.version = LowestVersionFor(material, file);
  }
  Writer w(file, result.version, result.notes);
  const bool v10 = result.version == SchemaVersion::k1_0;
  const std::string mp = "/material";

  if (material.name.empty()) throw InputError(file, mp + "/name", "expected a non-empty material name");
  if (!material.custom.is_null() && !material.custom.is_object())
    throw InputError(file, "/custom", "expected an object of vendor sections or null");
  if (!material.metadata.is_null() && !material.metadata.is_object())
    throw InputError(file, mp + "/metadata", "expected an object or null");

  std::string id = material.id;
  std::transform(id.begin(), id.end(), id.begin(), [](unsigned char c) { return std::tolower(c); });
  if (!IsUuid4(id)) {
    const std::string fresh = NewUuid4();
    result.notes.push_back({IssueSeverity::kWarning, mp + "/id",
                            "\"" + material.id + "\" is not a version-4 UUID; wrote the new id " + fresh});
    id = fresh;
  }

  JsonValue m = JsonValue::Object();
  m.Set("id", JsonValue::String(id));
  m.Set("name", JsonValue::String(material.name));
  m.Set("description", JsonValue::String(material.description));
  m.Set("created", JsonValue::String(FormatUtcTimestamp(material.created_ms)));
  m.Set("modified", JsonValue::String(FormatUtcTimestamp(material.modified_ms)));
  m.Set("front", w.Side(material.front, mp + "/front"));
  m.Set("back", w.Side(material.back, mp + "/back"));
  if (!v10) {
    m.Set("side", w.Side(material.side, mp + "/side"));
    m.Set("physics", w.PhysicsSection(material.physics, mp + "/physics"));
    m.Set("metadata", material.metadata);
  }

  JsonValue root = JsonValue::Object();
  root.Set("schema", JsonValue::String(std::string(SchemaVersionName(result.version))));
  root.Set("material", std::move(m));
  root.Set("custom", material.custom);
  result.text = WriteJson(root, options.indent);
  return result;
}

}  // namespace u3mscan

#pragma once
// Shared helpers of the u3m tests: temporary folders, inline U3M documents, tolerant JSON compare.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "tests/support/temp_dir.h"
#include "u3m/json_value.h"
#include "u3m/material.h"

namespace u3mscan::test {

namespace fs = std::filesystem;

// Relative tolerance for numbers that went through a unit conversion (cm <-> mm, degrees <-> turns):
// a few ulps of double rounding, nothing a writer may change on purpose.
inline constexpr double kConversionRelTol = 1e-12;

inline std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

inline void WriteFile(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << text;
}

inline bool SharedReferencePresent() { return fs::exists(fs::path(U3MSCAN_SHARED_DIR) / "reference/u3m"); }
inline fs::path SharedReference() { return fs::path(U3MSCAN_SHARED_DIR) / "reference/u3m"; }

// Compares two JSON documents; numbers within kConversionRelTol. Returns the first difference's
// pointer and reason, or "" when they agree.
inline std::string JsonDifference(const JsonValue& a, const JsonValue& b, const std::string& pointer = "") {
  if (a.type() != b.type()) return pointer + ": types differ";
  switch (a.type()) {
    case JsonValue::Type::kNumber: {
      const double scale = std::max({1.0, std::abs(a.number()), std::abs(b.number())});
      if (std::abs(a.number() - b.number()) > kConversionRelTol * scale)
        return pointer + ": " + a.text() + " != " + b.text();
      return "";
    }
    case JsonValue::Type::kArray:
      if (a.items().size() != b.items().size()) return pointer + ": array sizes differ";
      for (std::size_t i = 0; i < a.items().size(); ++i)
        if (auto d = JsonDifference(a.items()[i], b.items()[i], pointer + "/" + std::to_string(i)); !d.empty()) return d;
      return "";
    case JsonValue::Type::kObject:
      if (a.members().size() != b.members().size()) return pointer + ": member counts differ";
      for (std::size_t i = 0; i < a.members().size(); ++i) {
        if (a.members()[i].first != b.members()[i].first)
          return pointer + ": key " + a.members()[i].first + " != " + b.members()[i].first;
        if (auto d = JsonDifference(a.members()[i].second, b.members()[i].second, pointer + "/" + a.members()[i].first); !d.empty())
          return d;
      }
      return "";
    default:
      return a == b ? "" : pointer + ": values differ";
  }
}

// A foreign vendor section with number spellings a double round trip would change.
inline constexpr const char* kForeignCustom = R"({
        "OtherVendor": {
            "z_first": 0.49803921580314639,
            "trailing_zero": 1.0,
            "exponent": 1E5,
            "negative_zero": -0.0,
            "big": 123456789012345678901234567890,
            "precise": 0.1000000000000000055511151231257827,
            "list": [1, 2.50, {"deep": [true, false, null]}],
            "text": "caf\u00e9 \"quoted\" \\ slash",
            "a_last": {}
        },
        "Another": {"k": 3.14159265358979323846}
    })";

// A 1.1 document: front with textures, back null, side, physics, metadata, foreign custom.
inline std::string Inline11(const std::string& custom = kForeignCustom) {
  return R"({
    "schema": "1.1",
    "material": {
        "id": "{8B0A3C5E-1F2D-4E6A-9B7C-0D1E2F3A4B5C}",
        "name": "Inline 1.1",
        "description": "test",
        "created": "2021-10-19T15:41:23",
        "modified": "2022-01-02T03:04:05.250+01:00",
        "front": {
            "alpha": {"constant": 1.0, "texture": null},
            "anisotropy_value": {"constant": 0.2, "texture": null},
            "anisotropy_rotation": {"constant": 0.25, "texture": {"factor": 1.0, "offset": 0.125, "image": {"dpi": {"x": 300, "y": 300}, "height": 50.8, "path": "textures/aniso.png", "repeat": {"mode": "mirror_x", "rotation": 0.0}, "width": 25.4}}},
            "basecolor": {"constant": {"r": 0.25, "g": 0.5, "b": 0.75}, "texture": {"factor": {"r": 1, "g": 0.9, "b": 0.8}, "image": {"dpi": {"x": 300, "y": 150}, "height": 50.8, "path": "textures/base color.png", "repeat": {"mode": "normal", "rotation": 12.5}, "width": 25.4}, "mode": "multiply"}},
            "clearcoat_normal": {"constant": {"x": 0, "y": 0, "z": 1}, "texture": null},
            "clearcoat_roughness": {"constant": 0.0, "texture": null},
            "clearcoat_value": {"constant": 0.0, "texture": null},
            "displacement": {"constant": 0.5, "texture": {"factor": 2.0, "offset": -0.5, "image": {"dpi": {"x": 300, "y": 300}, "height": 50.8, "path": "textures/disp.png", "repeat": {"mode": "normal", "rotation": 0.0}, "width": 25.4}}},
            "ior": {"constant": 1.5, "texture": null},
            "metalness": {"constant": 0.0, "texture": null},
            "normal": {"constant": {"x": 0.1, "y": -0.2, "z": 0.97}, "texture": {"image": {"dpi": {"x": 300, "y": 300}, "height": 50.8, "path": "textures/normal.png", "repeat": {"mode": "normal", "rotation": 0.0}, "width": 25.4}, "scale": 1.5}},
            "preview": {"dpi": {"x": 72, "y": 72}, "height": 70.0, "path": "preview.png", "width": 70.0},
            "roughness": {"constant": 0.7, "texture": null},
            "shader": "principled",
            "sheen_tint": {"constant": 0.0, "texture": null},
            "sheen_value": {"constant": 0.3, "texture": null},
            "specular_tint": {"constant": 0.0, "texture": null},
            "specular_value": {"constant": 0.5, "texture": null},
            "subsurface_color": {"constant": {"r": 0, "g": 0, "b": 0}, "texture": null},
            "subsurface_radius": {"constant": 0.0, "texture": null},
            "subsurface_value": {"constant": 0.0, "texture": null},
            "transmission": {"constant": 0.0, "texture": null}
        },
        "back": null,
        "side": null,
        "physics": {
            "thickness": 0.8, "weight": 210.5, "devices": {"fab": "null"},
            "composition": {"parts": [{"ratio": 0.6, "type": "Cotton", "name": null}, {"ratio": 0.4, "type": "other", "name": "Seacell"}]},
            "material_type": {"type": "Woven", "name": null},
            "construction": null
        },
        "metadata": {"Order": {"z": 1, "a": 2.000}}
    },
    "custom": )" + custom + R"(
})";
}

// A 1.0 document: centimetres, one dpi number, degrees, braces in the id, back null.
// `transmission` is given as `transmission_value` so tests can substitute it (e.g. with null).
inline std::string Inline10(const std::string& transmission_value = R"({"constant": 0.1, "texture": null})") {
  return R"({
    "schema": "1.0",
    "custom": {"Vizoo": {"camera": "D810", "focal_length": 60.0}},
    "material": {
        "id": "{45d231aa-96a0-4d94-9aae-4a99fae0e32a}",
        "modified": "2018-07-16T10:40:00Z",
        "name": "Inline 1.0",
        "created": "2018-07-16T12:38:00+02:00",
        "description": "",
        "back": null,
        "front": {
            "shader": "principled",
            "alpha": {"constant": 1, "texture": null},
            "anisotropy_value": {"constant": 0.5, "texture": null},
            "anisotropy_rotation": {"constant": 90, "texture": {"factor": 360, "offset": 45, "image": {"dpi": 254, "height": 2.54, "width": 5.08, "path": "textures/aniso.png", "repeat": {"mode": "normal", "rotation": 0}}}},
            "basecolor": {"constant": {"r": 0.2, "g": 0.3, "b": 0.4}, "texture": {"mode": "multiply", "factor": {"r": 1, "g": 1, "b": 1}, "image": {"dpi": 254, "height": 2.54, "width": 5.08, "path": "textures/base.png", "repeat": {"mode": "mirror_xy", "rotation": 90}}}},
            "clearcoat_value": {"constant": 0, "texture": null},
            "clearcoat_normal": {"constant": 0, "texture": null},
            "clearcoat_roughness": {"constant": 0, "texture": null},
            "ior": {"constant": 1.45, "texture": null},
            "metalness": {"constant": 0, "texture": null},
            "normal": {"constant": 0, "texture": {"factor": 2, "offset": 0, "image": {"dpi": 254, "height": 2.54, "width": 5.08, "path": "textures/normal.png", "repeat": {"mode": "normal", "rotation": 0}}}},
            "displacement": {"constant": 0.25, "texture": {"factor": 1, "offset": 0, "image": {"dpi": 254, "height": 2.54, "width": 5.08, "path": "textures/disp.png", "repeat": {"mode": "normal", "rotation": 0}}}},
            "roughness": {"constant": 0.8, "texture": null},
            "sheen_value": {"constant": 0.2, "texture": null},
            "sheen_tint": {"constant": 0.1, "texture": null},
            "specular_value": {"constant": 0.5, "texture": null},
            "specular_tint": {"constant": 0, "texture": null},
            "subsurface_color": {"constant": {"r": 1, "g": 1, "b": 1}, "texture": null},
            "subsurface_radius": {"constant": 0, "texture": null},
            "subsurface_value": {"constant": 0, "texture": null},
            "transmission": )" + transmission_value + R"(
        }
    }
})";
}

}  // namespace u3mscan::test

// `u3mscan info FILE`: a short human summary of a U3M/U3MA.
#include <cstdio>
#include <iostream>
#include <memory>
#include <set>

#include "cli/command.h"
#include "u3m/material_io.h"

namespace u3mscan::cli {
namespace {

std::string Fmt(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.4g", v);
  return buffer;
}

void PrintSide(std::string_view name, const Visualization& side) {
  std::vector<std::string> maps;
  std::set<std::string> sizes;
  for (Visualization copy = side; const TextureRef& ref : TextureImages(copy)) {
    maps.emplace_back(ref.key);
    const TextureImage& i = *ref.image;
    sizes.insert(Fmt(i.width_mm) + " x " + Fmt(i.height_mm) + " mm at " +
                 (i.dpi_x == i.dpi_y ? Fmt(i.dpi_x) : Fmt(i.dpi_x) + " x " + Fmt(i.dpi_y)) + " dpi");
  }
  std::cout << "  " << name << ":\n    maps:      ";
  if (maps.empty()) std::cout << "none (constants only)";
  for (std::size_t i = 0; i < maps.size(); ++i) std::cout << (i ? ", " : "") << maps[i];
  std::cout << "\n";
  for (const std::string& size : sizes) std::cout << "    size:      " << size << "\n";
  const Rgb3& c = side.basecolor.constant;
  std::cout << "    basecolor: (" << Fmt(c.r) << ", " << Fmt(c.g) << ", " << Fmt(c.b) << ") linear"
            << ", roughness " << Fmt(side.roughness.constant) << ", metalness " << Fmt(side.metalness.constant)
            << ", sheen " << Fmt(side.sheen_value.constant) << "\n";
  if (side.preview) std::cout << "    preview:   " << side.preview->path << "\n";
}

U3MSCAN_REGISTER_COMMAND(kInfoCommand, "info", "Summarise a U3M/U3MA: name, version, sides, maps, size, dpi", 40,
                         [](CLI::App& sub) {
  auto file = std::make_shared<std::string>();
  sub.add_option("FILE", *file, "A .u3m or .u3ma file")->required();
  sub.footer("Reads the JSON only (no pixels). 'u3mscan validate' checks the files and values.");
  return std::function<int()>([file] {
    const LoadedMaterial loaded = LoadMaterial(*file);
    const Material& m = loaded.material;
    std::cout << *file << "\n"
              << "  name:      " << m.name << "\n"
              << "  schema:    U3M " << SchemaVersionName(loaded.version) << "\n"
              << "  id:        " << m.id << "\n"
              << "  created:   " << FormatUtcTimestamp(m.created_ms) << "\n"
              << "  modified:  " << FormatUtcTimestamp(m.modified_ms) << "\n";
    std::cout << "  sides:     ";
    const auto sides = Sides(m);
    if (sides.empty()) std::cout << "none";
    for (std::size_t i = 0; i < sides.size(); ++i) std::cout << (i ? ", " : "") << sides[i].first;
    if (m.front && !m.back) std::cout << " (back uses front)";
    std::cout << "\n";
    for (const auto& [name, side] : sides) PrintSide(name, *side);
    if (m.physics) {
      const Physics& p = *m.physics;
      std::cout << "  physics:   thickness " << (p.thickness_mm ? Fmt(*p.thickness_mm) + " mm" : "-") << ", weight "
                << (p.weight_g_per_m2 ? Fmt(*p.weight_g_per_m2) + " g/m2" : "-")
                << (p.fab_path.empty() ? "" : ", FAB " + p.fab_path) << "\n";
    }
    std::cout << "  custom:    ";
    if (!m.custom.is_object() || m.custom.members().empty()) std::cout << "none";
    else
      for (std::size_t i = 0; i < m.custom.members().size(); ++i) std::cout << (i ? ", " : "") << m.custom.members()[i].first;
    std::cout << "\n";
    int errors = 0;
    for (const Issue& issue : loaded.issues) errors += issue.severity == IssueSeverity::kError;
    if (!loaded.issues.empty())
      std::cout << "  reading:   " << errors << " errors, " << loaded.issues.size() - errors
                << " warnings (see 'u3mscan validate')\n";
    return kExitOk;
  });
});

}  // namespace
}  // namespace u3mscan::cli

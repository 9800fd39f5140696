#pragma once
// A complete example U3M from built-in values: a small plain-weave fabric with procedural
// basecolor, normal, roughness and displacement maps, our custom section, and (for 1.1) a preview
// and physics. It exercises every writer rule until the scan pipeline produces real materials.

#include <filesystem>
#include <optional>
#include <string>

#include "u3m/material_io.h"

namespace u3mscan {

struct ExampleOptions {
  std::string name = "u3mscan example plain weave";
  int size_px = 256;       // square maps; one weave repeat every 16 px, so keep it a multiple of 16
  double pitch_mm = 0.1;   // physical pixel size (254 dpi)
  std::optional<SchemaVersion> version;  // unset: full content, written as the lowest version that holds it (1.1)
  bool overwrite = false;  // an earlier example at the same place is replaced anyway
  bool Check(std::string* why) const;
};

// Writes the example to `out` (.u3m with a textures/ folder beside it, or one .u3ma).
// Throws InputError on bad options or when the output cannot be written.
SaveResult WriteExampleMaterial(const std::filesystem::path& out, const ExampleOptions& options);

}  // namespace u3mscan

// libFuzzer target: the U3M JSON reader, schema 1.0 and 1.1 (u3m/material_json.h).
//
// Contract under test: ReadMaterialJson either returns a material (with tolerated deviations as
// issues) or throws InputError; nothing else escapes. Whatever it returns, the writer either writes
// it or refuses with InputError, and what the writer writes reads back without an error (a
// rewrite of a tolerated file is a valid file). Both the file's own version and the automatic
// (lowest) version are written, so the 1.0 and 1.1 writers are exercised from every input.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>

#include "core/error.h"
#include "u3m/material_json.h"

namespace {

constexpr const char* kSourceName = "fuzz/material.u3m";

void RewriteAndReread(const u3mscan::Material& material, std::optional<u3mscan::SchemaVersion> version) {
  u3mscan::MaterialWriteOptions options;
  options.version = version;
  u3mscan::MaterialWriteResult written;
  try {
    written = u3mscan::WriteMaterialJson(material, options, "fuzz/out.u3m");
  } catch (const u3mscan::InputError&) {
    return;  // e.g. a 1.1-only feature asked to be written as 1.0: a documented refusal
  }
  try {
    const u3mscan::MaterialReadResult again = u3mscan::ReadMaterialJson(written.text, "fuzz/out.u3m");
    for (const u3mscan::Issue& issue : again.issues) {
      if (issue.severity == u3mscan::IssueSeverity::kError) {
        std::fprintf(stderr, "the writer wrote a schema error at %s: %s\n%s\n", issue.pointer.c_str(),
                     issue.message.c_str(), written.text.c_str());
        std::abort();
      }
    }
  } catch (const u3mscan::InputError& e) {
    std::fprintf(stderr, "the writer's own output does not read back: %s\n%s\n", e.what(), written.text.c_str());
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  u3mscan::MaterialReadResult read;
  try {
    read = u3mscan::ReadMaterialJson(text, kSourceName);
  } catch (const u3mscan::InputError&) {
    return 0;
  }
  RewriteAndReread(read.material, std::nullopt);
  RewriteAndReread(read.material, read.version);
  return 0;
}

// libFuzzer target: the capture manifest parser (capture/manifest.h, ParseManifest).
//
// Contract under test: any byte string either parses into a Manifest or throws InputError; nothing
// else escapes (no other exception, no crash, no sanitizer report). A manifest that parses must
// survive ManifestToJson -> ParseManifest unchanged (the header promises the round trip).
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstdio>
#include <string>

#include "capture/manifest.h"
#include "core/error.h"

namespace {
constexpr const char* kSourceName = "fuzz/capture.json";
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  u3mscan::Manifest manifest;
  try {
    manifest = u3mscan::ParseManifest(text, kSourceName);
  } catch (const u3mscan::InputError&) {
    return 0;  // refused with a message: the expected outcome for most inputs
  }
  const nlohmann::json written = u3mscan::ManifestToJson(manifest);
  try {
    const u3mscan::Manifest again = u3mscan::ParseManifest(written.dump(), kSourceName);
    if (u3mscan::ManifestToJson(again) != written) {
      std::fprintf(stderr, "manifest round trip changed the content:\n%s\n", written.dump(2).c_str());
      std::abort();
    }
  } catch (const u3mscan::InputError& e) {
    std::fprintf(stderr, "a parsed manifest does not parse after ManifestToJson: %s\n", e.what());
    std::abort();
  }
  return 0;
}

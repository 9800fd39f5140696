#pragma once
// Ground truth of a synthetic capture on disk: one float EXR per map and truth.json with the
// parameters, units, grid and the renderer's light and camera geometry. Format in
// docs/synthetic-scenes.md.

#include <filesystem>

#include <nlohmann/json.hpp>

#include "datasets_synthetic/scene.h"

namespace u3mscan::synthetic {

// Writes `dir`/ (truth.json + <map>.exr, float32, linear). `extra` must be a JSON object (or null);
// its members are added to truth.json's top level (the renderer passes its "lights", "cameras",
// ...); a member that collides with one of ours throws std::invalid_argument. Atomic: everything is
// written into a temporary sibling directory which then replaces `dir`. Throws InputError naming
// the file when writing fails.
void WriteTruth(const SceneTruth& truth, const nlohmann::json& extra, const std::filesystem::path& dir);

// Reads what WriteTruth wrote (maps, name, pitch, seed, model, height range, repeat, yarns).
// `json_out` receives truth.json as written. Throws InputError naming the file and field.
SceneTruth ReadTruth(const std::filesystem::path& dir, nlohmann::json* json_out = nullptr);

}  // namespace u3mscan::synthetic

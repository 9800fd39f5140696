#pragma once
// The bench's own fabric scenes: small procedural stand-ins for the synthetic scanner's presets
// (datasets_synthetic/scene.h MakeScene), so that the bench runs before and independently of them.
// Each is a height field with analytic normals and per-pixel Principled parameters:
//
//   plain   plain weave (warp/weft basket), two yarn colours, matte (roughness 0.75, specular 0.4)
//   satin   long floats along x, glossy (roughness 0.35, specular 0.7), one colour
//   velvet  short pile bumps, dark red, rough with strong sheen (sheen 0.8, tint 0.5)
//   lace    plain weave with round holes (alpha 0), for the backlight/alpha path
//
// Units: mm; colours linear RGB. Grid as SceneTruth: pixel (col, row) at x = (col + 0.5) p,
// y = -(row + 0.5) p relative to the sample's top-left corner.

#include <cstdint>
#include <string>
#include <vector>

#include "datasets_synthetic/scene.h"

namespace u3mscan::bench {

std::vector<std::string> BenchSceneNames();
// Throws std::invalid_argument for an unknown name.
synthetic::SceneTruth MakeBenchScene(const std::string& name, int width, int height, double pitch_mm,
                                     std::uint64_t seed);

}  // namespace u3mscan::bench

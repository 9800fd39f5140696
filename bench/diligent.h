#pragma once
// `u3mscan bench --diligent ROOT`: photometric stereo on real photographs whose normals are known,
// in the folder format of the DiLiGenT benchmark (Shi et al., CVPR 2016; layout in
// datasets_synthetic/diligent_ball.h, which writes a synthetic object in it). Each object is read
// into a Stack (directional lights, an orthographic view, the observations divided by each
// light's intensity, pixels off the mask out of view, clipped pixels saturated), solved by
// reconstruction/photometric_stereo.h with each method, and its normals compared with the truth
// over the mask: the figures the DiLiGenT paper tabulates (mean angular error, degrees).

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/stack.h"

namespace u3mscan::bench {

struct DiLiGenTObject {
  std::string name;  // the folder's name (ballPNG, ...)
  // Cropped to the mask's bounding box (plus one pixel): grid pitch 1 mm, x to the right, y up.
  Stack stack;
  Image true_normal;                 // 3 channels on the stack's grid; 0 0 0 off the object
  std::vector<std::uint8_t> on_object;  // 1 where mask.png is non-zero and the truth is a unit vector
  long long saturated_observations = 0;
};

// The object folders under `root`: root itself when it holds light_directions.txt, else its
// sub-folders that do (DiLiGenT's pmsData), sorted by name. Throws InputError naming root when
// there are none.
std::vector<std::filesystem::path> FindDiLiGenTObjects(const std::filesystem::path& root);

// The text files alone (filenames.txt, light_directions.txt, light_intensities.txt, and that the
// images, mask.png and the ground truth exist): a bad folder is found before any image is read.
// Throws InputError naming the file, the line and what was expected.
void CheckDiLiGenTObject(const std::filesystem::path& dir);

// Reads one object folder. Throws InputError naming the file (and the line of a text file) and
// what was expected: a missing or malformed text file, counts that disagree, an image whose size
// differs from mask.png, a ground truth with the wrong number of lines. The ground truth is read
// from Normal_gt.txt (or normal.txt); DiLiGenT also ships it as Normal_gt.mat, which is not read
// (the message says how to convert it).
DiLiGenTObject ReadDiLiGenTObject(const std::filesystem::path& dir);

// One method on one object.
struct DiLiGenTRun {
  std::string object;
  int lights = 0;
  long long pixels = 0;        // compared (on the object)
  std::string solver;          // ls | robust
  std::string diffuse_model;   // lambert | burley
  double diffuse_roughness = -1;  // the Burley roughness the solve used; -1: Lambert's law
  double mean_deg = 0, median_deg = 0, p95_deg = 0;
  long long ill_conditioned_pixels = 0;  // on the object: condition number >= the solver's max_condition
  double seconds = 0;          // the solve alone, wall
};

// Every method (ls and robust, each with the Lambert and the Burley diffuse model; the pipeline's
// other photometric-stereo options at their defaults) on one object.
std::vector<DiLiGenTRun> RunDiLiGenTMethods(const DiLiGenTObject& object);

// Checks every object under root first (nothing is written for a bad one), then reads and runs
// them one at a time and writes out_dir/diligent.csv and out_dir/diligent.md (created). Throws
// InputError for a bad root, object or output folder.
std::vector<DiLiGenTRun> RunDiLiGenTBench(const std::filesystem::path& root, const std::filesystem::path& out_dir);

}  // namespace u3mscan::bench

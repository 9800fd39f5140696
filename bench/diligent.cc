// DiLiGenT-format objects: reading (text files, images, mask, truth), the methods, the tables.
#include "bench/diligent.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include "bench/error_stats.h"
#include "bench/table_cells.h"
#include "core/elapsed.h"
#include "core/error.h"
#include "core/logging.h"
#include "core/text_file.h"
#include "core/units.h"
#include "reconstruction/photometric_stereo.h"
#include "u3m/image_io.h"

namespace u3mscan::bench {
namespace fs = std::filesystem;

namespace {

// An orthographic camera: the view's centre this far above the grid (mm) turns the view
// direction by less than 1e-4 deg over a 1000 px crop.
constexpr double kOrthographicDistanceMm = 1e7;
const char* const kTruthFiles[] = {"Normal_gt.txt", "normal.txt"};

struct TextLine {
  int number = 0;  // 1-based, as an editor shows it
  std::string text;
};

// The file's lines that hold anything but white space.
std::vector<TextLine> ReadNonBlankLines(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path.string(), "", "a readable text file (the DiLiGenT object folder layout: docs/reconstruction.md)");
  std::vector<TextLine> lines;
  std::string text;
  for (int number = 1; std::getline(in, text); ++number) {
    if (!text.empty() && text.back() == '\r') text.pop_back();
    if (text.find_first_not_of(" \t") != std::string::npos) lines.push_back({number, text});
  }
  return lines;
}

// Exactly three finite numbers, separated by spaces, tabs or commas.
Eigen::Vector3d ParseTriple(const fs::path& path, const TextLine& line, const char* what) {
  Eigen::Vector3d v;
  const char* p = line.text.data();
  const char* end = p + line.text.size();
  auto skip = [&] { while (p < end && (*p == ' ' || *p == '\t' || *p == ',')) ++p; };
  for (int i = 0; i < 3; ++i) {
    skip();
    const auto [next, ec] = std::from_chars(p, end, v(i));
    if (ec != std::errc() || !std::isfinite(v(i))) {
      throw InputError(path.string(), "line " + std::to_string(line.number), std::string("three numbers (") + what + "), got '" + line.text + "'");
    }
    p = next;
  }
  skip();
  if (p != end) throw InputError(path.string(), "line " + std::to_string(line.number), std::string("three numbers (") + what + ") and nothing else, got '" + line.text + "'");
  return v;
}

std::vector<Eigen::Vector3d> ReadTriples(const fs::path& path, const char* what) {
  std::vector<Eigen::Vector3d> values;
  for (const TextLine& line : ReadNonBlankLines(path)) values.push_back(ParseTriple(path, line, what));
  return values;
}

// What the text files of an object say, checked against each other.
struct ObjectLayout {
  std::vector<std::string> image_names;
  std::vector<Eigen::Vector3d> directions;   // unit
  std::vector<Eigen::Vector3d> intensities;  // > 0
  fs::path truth;
};

ObjectLayout ReadLayout(const fs::path& dir) {
  ObjectLayout layout;
  const fs::path names_path = dir / "filenames.txt";
  for (const TextLine& line : ReadNonBlankLines(names_path)) {
    const auto first = line.text.find_first_not_of(" \t"), last = line.text.find_last_not_of(" \t");
    const std::string name = line.text.substr(first, last - first + 1);
    if (!fs::is_regular_file(dir / name)) {
      throw InputError(names_path.string(), "line " + std::to_string(line.number), "the name of an image in " + dir.string() + ", got '" + name + "' (no such file)");
    }
    layout.image_names.push_back(name);
  }
  if (layout.image_names.size() < 3) throw InputError(names_path.string(), "", "at least 3 images (photometric stereo needs 3 lights)");
  const std::size_t count = layout.image_names.size();

  const fs::path directions_path = dir / "light_directions.txt";
  layout.directions = ReadTriples(directions_path, "x y z toward the light");
  const fs::path intensities_path = dir / "light_intensities.txt";
  layout.intensities = ReadTriples(intensities_path, "r g b intensity");
  auto check_count = [&](const fs::path& path, std::size_t n) {
    if (n != count) throw InputError(path.string(), "", "one line per image of filenames.txt (" + std::to_string(count) + "), got " + std::to_string(n));
  };
  check_count(directions_path, layout.directions.size());
  check_count(intensities_path, layout.intensities.size());
  for (std::size_t k = 0; k < count; ++k) {
    const double norm = layout.directions[k].norm();
    if (!(norm > 1e-6)) throw InputError(directions_path.string(), "light " + std::to_string(k + 1), "a direction of non-zero length");
    layout.directions[k] /= norm;
    if (!(layout.intensities[k].array() > 0.0).all()) {
      throw InputError(intensities_path.string(), "light " + std::to_string(k + 1), "a positive intensity in each channel");
    }
  }

  if (!fs::is_regular_file(dir / "mask.png")) throw InputError((dir / "mask.png").string(), "", "the object's mask (non-zero on the object)");
  for (const char* name : kTruthFiles) {
    if (fs::is_regular_file(dir / name)) {
      layout.truth = dir / name;
      break;
    }
  }
  if (layout.truth.empty()) {
    std::string expected = "the true normals as text: width x height lines 'nx ny nz', row-major (also read from normal.txt)";
    if (fs::is_regular_file(dir / "Normal_gt.mat")) {
      expected += "; only Normal_gt.mat is here, which is not read: convert it once with python3 -c \"import numpy, scipy.io; "
                  "numpy.savetxt('Normal_gt.txt', scipy.io.loadmat('Normal_gt.mat')['Normal_gt'].reshape(-1, 3))\"";
    }
    throw InputError((dir / kTruthFiles[0]).string(), "", expected);
  }
  return layout;
}

// The 3 colour channels of an image as read (a grey image gives its one channel three times).
float Channel(const Image& image, int c, int row, int col) { return image.at(image.channels() >= 3 ? c : 0, row, col); }

// The part of the image the object is solved on: the mask's bounding box and one pixel around it
// (the neighbours the stability rules read).
struct Crop {
  int col0 = 0, row0 = 0, width = 0, height = 0;
};

Crop CropAroundMask(const Image& mask, const fs::path& mask_path) {
  int col0 = mask.width(), col1 = -1, row0 = mask.height(), row1 = -1;
  for (int row = 0; row < mask.height(); ++row) {
    for (int col = 0; col < mask.width(); ++col) {
      if (mask.at(0, row, col) > 0.0f) col0 = std::min(col0, col), col1 = std::max(col1, col), row0 = std::min(row0, row), row1 = std::max(row1, row);
    }
  }
  if (col1 < 0) throw InputError(mask_path.string(), "", "a mask with the object non-zero (every pixel is 0)");
  col0 = std::max(0, col0 - 1), row0 = std::max(0, row0 - 1);
  col1 = std::min(mask.width() - 1, col1 + 1), row1 = std::min(mask.height() - 1, row1 + 1);
  return {col0, row0, col1 - col0 + 1, row1 - row0 + 1};
}

bool InMask(const Image& mask, const Crop& crop, int row, int col) { return mask.at(0, crop.row0 + row, crop.col0 + col) > 0.0f; }

// The true normals of the crop's mask pixels (one text line per pixel of the whole image) into
// object->true_normal and object->on_object.
void ReadTrueNormals(const fs::path& truth_path, const Image& mask, const Crop& crop, DiLiGenTObject* object) {
  const int width = mask.width(), height = mask.height();
  const std::vector<TextLine> truth_lines = ReadNonBlankLines(truth_path);
  if (truth_lines.size() != static_cast<std::size_t>(width) * height) {
    throw InputError(truth_path.string(), "", std::to_string(width) + " x " + std::to_string(height) + " = " +
                                                  std::to_string(static_cast<long long>(width) * height) +
                                                  " lines 'nx ny nz' (mask.png's size), got " + std::to_string(truth_lines.size()));
  }
  object->true_normal = Image(crop.width, crop.height, 3, 0.0f, 1.0);
  object->on_object.assign(static_cast<std::size_t>(crop.width) * crop.height, 0);
  for (int row = 0; row < crop.height; ++row) {
    for (int col = 0; col < crop.width; ++col) {
      if (!InMask(mask, crop, row, col)) continue;
      const TextLine& line = truth_lines[static_cast<std::size_t>(crop.row0 + row) * width + crop.col0 + col];
      const Eigen::Vector3d n = ParseTriple(truth_path, line, "nx ny nz");
      // A pixel of the mask without a unit truth (DiLiGenT writes 0 0 0 off the object) is not compared.
      if (std::abs(n.norm() - 1.0) > 0.1) continue;
      const Eigen::Vector3d unit = n.normalized();
      for (int c = 0; c < 3; ++c) object->true_normal.at(c, row, col) = static_cast<float>(unit(c));
      object->on_object[static_cast<std::size_t>(row) * crop.width + col] = 1;
    }
  }
}

// One light's image on the crop, divided by the light's intensity; off the mask out of view,
// clipped pixels saturated (counted on the object into *saturated).
Observation ReadObservation(const fs::path& image_path, int light, const Eigen::Vector3d& intensity, const Image& mask,
                            const Crop& crop, long long* saturated) {
  const Image image = ReadImageFile(image_path, PixelEncoding::kLinear);
  if (image.width() != mask.width() || image.height() != mask.height()) {
    throw InputError(image_path.string(), "", std::to_string(mask.width()) + " x " + std::to_string(mask.height()) +
                                                  " pixels like mask.png, got " + std::to_string(image.width()) + " x " +
                                                  std::to_string(image.height()));
  }
  if (image.channels() != 1 && image.channels() < 3) throw InputError(image_path.string(), "", "a grey or RGB image");
  Observation obs;
  obs.view = 0;
  obs.light = light;
  obs.rgb = Image(crop.width, crop.height, 3, 0.0f, 1.0);
  obs.flags.assign(static_cast<std::size_t>(crop.width) * crop.height, 0);
  for (int row = 0; row < crop.height; ++row) {
    for (int col = 0; col < crop.width; ++col) {
      std::uint8_t& flags = obs.flags[static_cast<std::size_t>(row) * crop.width + col];
      if (!InMask(mask, crop, row, col)) flags |= kOutOfView;
      for (int c = 0; c < 3; ++c) {
        const float value = Channel(image, c, crop.row0 + row, crop.col0 + col);
        // Full scale is clipped: the sensor's white level (code 65535 of a 16-bit PNG reads 1).
        if (value >= 1.0f) flags |= kSaturated;
        obs.rgb.at(c, row, col) = static_cast<float>(value / intensity(c));
      }
      if ((flags & kSaturated) && !(flags & kOutOfView)) ++*saturated;
    }
  }
  return obs;
}

}  // namespace

std::vector<fs::path> FindDiLiGenTObjects(const fs::path& root) {
  if (fs::is_regular_file(root / "light_directions.txt")) return {root};
  std::vector<fs::path> objects;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(root, ec)) {
    if (entry.is_directory() && fs::is_regular_file(entry.path() / "light_directions.txt")) objects.push_back(entry.path());
  }
  std::sort(objects.begin(), objects.end());
  if (objects.empty()) {
    throw InputError(root.string(), "", "a DiLiGenT object folder (light_directions.txt, light_intensities.txt, filenames.txt, the images, "
                                        "mask.png, Normal_gt.txt) or a folder of them (DiLiGenT's pmsData)");
  }
  return objects;
}

void CheckDiLiGenTObject(const fs::path& dir) { ReadLayout(dir); }

DiLiGenTObject ReadDiLiGenTObject(const fs::path& dir) {
  const ObjectLayout layout = ReadLayout(dir);
  DiLiGenTObject object;
  object.name = dir.filename().string();
  if (object.name.empty()) object.name = dir.parent_path().filename().string();

  const fs::path mask_path = dir / "mask.png";
  const Image mask = ReadImageFile(mask_path, PixelEncoding::kLinear);
  const Crop crop = CropAroundMask(mask, mask_path);
  ReadTrueNormals(layout.truth, mask, crop, &object);

  Stack& stack = object.stack;
  stack.side = "front";
  stack.grid.width = crop.width;
  stack.grid.height = crop.height;
  stack.grid.pitch_mm = 1.0;
  stack.grid.x0_mm = 0.0;
  stack.grid.y1_mm = crop.height;
  stack.views.push_back({"camera", Eigen::Vector3d(0.5 * crop.width, 0.5 * crop.height, kOrthographicDistanceMm)});
  for (std::size_t k = 0; k < layout.image_names.size(); ++k) {
    LightModel light;
    light.id = fs::path(layout.image_names[k]).stem().string();
    light.type = LightType::kDirectional;
    light.direction_in_world = layout.directions[k];
    light.intensity_rgb = layout.intensities[k];
    stack.lights.push_back(light);
    stack.observations.push_back(ReadObservation(dir / layout.image_names[k], static_cast<int>(k), layout.intensities[k], mask,
                                                 crop, &object.saturated_observations));
  }
  return object;
}

std::vector<DiLiGenTRun> RunDiLiGenTMethods(const DiLiGenTObject& object) {
  using reconstruction::DiffuseModel;
  using reconstruction::PsSolver;
  const std::pair<PsSolver, DiffuseModel> methods[] = {{PsSolver::kLeastSquares, DiffuseModel::kLambert},
                                                      {PsSolver::kLeastSquares, DiffuseModel::kBurley},
                                                      {PsSolver::kRobust, DiffuseModel::kLambert},
                                                      {PsSolver::kRobust, DiffuseModel::kBurley}};
  std::vector<DiLiGenTRun> runs;
  for (const auto& [solver, diffuse] : methods) {
    reconstruction::PhotometricStereoOptions options;
    options.solver = solver;
    options.diffuse_model = diffuse;
    const double start = SteadySeconds();
    const reconstruction::PhotometricStereoResult result = reconstruction::RunPhotometricStereo(object.stack, options);
    DiLiGenTRun run;
    run.seconds = SteadySeconds() - start;
    run.object = object.name;
    run.lights = static_cast<int>(object.stack.lights.size());
    run.solver = reconstruction::PsSolverName(solver);
    run.diffuse_model = reconstruction::DiffuseModelName(diffuse);
    run.diffuse_roughness = result.diffuse_roughness;

    const int w = object.true_normal.width(), h = object.true_normal.height();
    std::vector<float> angles;
    for (int row = 0; row < h; ++row) {
      for (int col = 0; col < w; ++col) {
        if (!object.on_object[static_cast<std::size_t>(row) * w + col]) continue;
        if (result.condition_number.at(0, row, col) >= options.max_condition) ++run.ill_conditioned_pixels;
        Eigen::Vector3d truth, estimate;
        for (int c = 0; c < 3; ++c) truth(c) = object.true_normal.at(c, row, col), estimate(c) = result.normal.at(c, row, col);
        angles.push_back(static_cast<float>(RadToDeg(std::atan2(truth.cross(estimate).norm(), truth.dot(estimate)))));
      }
    }
    run.pixels = static_cast<long long>(angles.size());
    const ErrorStats stats = Summarise(std::move(angles));
    run.mean_deg = stats.mean;
    run.median_deg = stats.median;
    run.p95_deg = stats.p95;
    LogInfo() << "diligent: " << run.object << " " << run.solver << "/" << run.diffuse_model << ": mean " << Fixed(run.mean_deg, 2)
              << " deg over " << run.pixels << " px in " << Fixed(run.seconds, 2) << " s";
    runs.push_back(run);
  }
  return runs;
}

std::vector<DiLiGenTRun> RunDiLiGenTBench(const fs::path& root, const fs::path& out_dir) {
  const std::vector<fs::path> objects = FindDiLiGenTObjects(root);
  for (const fs::path& dir : objects) CheckDiLiGenTObject(dir);
  std::vector<DiLiGenTRun> runs;
  for (const fs::path& dir : objects) {
    const DiLiGenTObject object = ReadDiLiGenTObject(dir);
    for (DiLiGenTRun& run : RunDiLiGenTMethods(object)) runs.push_back(std::move(run));
  }

  std::ostringstream csv, md;
  csv << "object,lights,pixels,solver,diffuse_model,diffuse_roughness,mean_deg,median_deg,p95_deg,ill_conditioned_pixels,seconds\n";
  md << "# Photometric stereo on DiLiGenT-format objects (`u3mscan bench --diligent " << root.string() << "`)\n\n"
     << "Mean angular error of the normals over each object's mask, degrees; the solve alone, wall seconds.\n\n"
     << "| object | lights | pixels | solver | diffuse model | diffuse roughness | mean deg | median deg | p95 deg | ill-conditioned px | s |\n"
     << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const DiLiGenTRun& r : runs) {
    const std::string roughness = r.diffuse_roughness >= 0 ? Fixed(r.diffuse_roughness, 3) : "";
    csv << Csv(r.object) << "," << r.lights << "," << r.pixels << "," << r.solver << "," << r.diffuse_model << "," << roughness << ","
        << Fixed(r.mean_deg, 3) << "," << Fixed(r.median_deg, 3) << "," << Fixed(r.p95_deg, 3) << "," << r.ill_conditioned_pixels << ","
        << Fixed(r.seconds, 3) << "\n";
    md << "| " << r.object << " | " << r.lights << " | " << r.pixels << " | " << r.solver << " | " << r.diffuse_model << " | "
       << (roughness.empty() ? "Lambert's law" : roughness) << " | " << Fixed(r.mean_deg, 2) << " | " << Fixed(r.median_deg, 2) << " | "
       << Fixed(r.p95_deg, 2) << " | " << r.ill_conditioned_pixels << " | " << Fixed(r.seconds, 2) << " |\n";
  }
  md << "\nPublished for DiLiGenT's real `ball` (Shi et al. 2016): least squares 4.10 deg, the best classic robust method "
        "1.74 deg (mean angular error).\n";
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) throw InputError(out_dir.string(), "", "an output folder that can be created (" + ec.message() + ")");
  WriteTextFileAtomically(out_dir / "diligent.csv", csv.str(), "a writable output folder");
  WriteTextFileAtomically(out_dir / "diligent.md", md.str(), "a writable output folder");
  return runs;
}

}  // namespace u3mscan::bench

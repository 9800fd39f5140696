#include "u3m/material_io.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <system_error>

#include "core/error.h"
#include "core/units.h"
#include "u3m/image_io.h"
#include "u3m/relative_path.h"
#include "u3m/texture_stats.h"
#include "u3m/u3ma_archive.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

bool IsPackage(const fs::path& path) { return Lower(path.extension().string()) == ".u3ma"; }
bool IsU3m(const fs::path& path) { return Lower(path.extension().string()) == ".u3m"; }

std::string ReadText(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw InputError(path.string(), "", "expected an existing U3M file");
  const auto size = fs::file_size(path, ec);
  if (ec || size > kMaxJsonBytes)
    throw InputError(path.string(), "", "expected a readable U3M file of at most " + std::to_string(kMaxJsonBytes >> 20) + " MiB");
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  if (!in.good() && !in.eof()) throw InputError(path.string(), "", "expected a readable file");
  return text.str();
}

std::vector<std::uint8_t> ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string(), "", "expected a readable file");
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void WriteText(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  out.close();
  if (!out) throw InputError(path.string(), "", "expected a writable location");
}

std::string RandomTag() { return NewUuid4().substr(0, 8); }

// A file the material names, and how to forget it.
struct FileRef {
  std::string pointer;  // of the path in the written file
  std::string* path;
  std::function<void()> drop;
};

std::vector<FileRef> CollectFileRefs(Material& m) {
  std::vector<FileRef> refs;
  for (auto [name, side] : Sides(m)) {
    const std::string sp = "/material/" + std::string(name) + "/";
    for (const ScalarKey& key : ScalarKeys()) {
      ScalarParam& p = side->*key.member;
      if (p.texture) refs.push_back({sp + std::string(key.name) + "/texture/image/path", &p.texture->image.path, [&p] { p.texture.reset(); }});
    }
    for (const NormalKey& key : NormalKeys()) {
      NormalParam& p = side->*key.member;
      if (p.texture) refs.push_back({sp + std::string(key.name) + "/texture/image/path", &p.texture->image.path, [&p] { p.texture.reset(); }});
    }
    for (const ColorKey& key : ColorKeys()) {
      ColorParam& p = side->*key.member;
      if (p.texture) refs.push_back({sp + std::string(key.name) + "/texture/image/path", &p.texture->image.path, [&p] { p.texture.reset(); }});
    }
    if (side->preview) refs.push_back({sp + "preview/path", &side->preview->path, [side = side] { side->preview.reset(); }});
  }
  if (m.physics && !m.physics->fab_path.empty()) {
    Physics* physics = &*m.physics;
    refs.push_back({"/material/physics/devices/fab", &physics->fab_path, [physics] { physics->fab_path.clear(); }});
  }
  return refs;
}

std::string Fmt(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.6g", v);
  return buffer;
}

// Makes size and dpi agree with the pixel count (see SaveOptions::fix_image_geometry).
void FixGeometry(double& width_mm, double& height_mm, double& dpi_x, double& dpi_y, const ImageReadInfo& info,
                 bool keep_size, const std::string& pointer, std::vector<Issue>& notes) {
  if (PixelSizeAgrees(info.width, width_mm, dpi_x) && PixelSizeAgrees(info.height, height_mm, dpi_y)) return;
  const std::string before = Fmt(width_mm) + " x " + Fmt(height_mm) + " mm at " + Fmt(dpi_x) + " x " + Fmt(dpi_y) + " dpi";
  const bool square = dpi_x == dpi_y;
  if (keep_size && width_mm > 0.0 && height_mm > 0.0) {
    dpi_x = info.width * kMmPerInch / width_mm;
    dpi_y = square ? dpi_x : info.height * kMmPerInch / height_mm;
    if (square) height_mm = info.height * kMmPerInch / dpi_y;
  } else {
    if (!(dpi_x > 0.0 && dpi_y > 0.0)) {
      dpi_x = info.dpi_x > 0.0 ? info.dpi_x : 72.0;  // 72: the screen convention for pictures
      dpi_y = info.dpi_y > 0.0 ? info.dpi_y : dpi_x;
    }
    width_mm = info.width * kMmPerInch / dpi_x;
    height_mm = info.height * kMmPerInch / dpi_y;
  }
  notes.push_back({IssueSeverity::kWarning, pointer,
                   before + " disagreed with " + std::to_string(info.width) + " x " + std::to_string(info.height) +
                       " px; wrote " + Fmt(width_mm) + " x " + Fmt(height_mm) + " mm at " + Fmt(dpi_x) + " x " +
                       Fmt(dpi_y) + " dpi"});
}

void NoteConstant(std::vector<Issue>& notes, const std::string& pointer, const std::string& from, const std::string& to) {
  notes.push_back({IssueSeverity::kWarning, pointer, "constant " + from + " set to the texture mean " + to});
}

// Geometry and constants from the texture files (SaveOptions::fix_image_geometry, update_constants).
void UpdateFromTextures(Material& m, const fs::path& base_dir, const SaveOptions& options, std::vector<Issue>& notes) {
  for (auto [name, side] : Sides(m)) {
    const std::string sp = "/material/" + std::string(name) + "/";
    const auto geometry = [&](TextureImage& image, const std::string& pointer) {
      const ImageReadInfo info = ReadImageInfo(base_dir / image.path);
      if (options.fix_image_geometry)
        FixGeometry(image.width_mm, image.height_mm, image.dpi_x, image.dpi_y, info, true, pointer, notes);
    };
    for (const ScalarKey& key : ScalarKeys()) {
      ScalarParam& p = side->*key.member;
      if (!p.texture) continue;
      const std::string kp = sp + std::string(key.name);
      geometry(p.texture->image, kp + "/texture/image");
      if (!options.update_constants) continue;
      const Image image = ReadImageFile(base_dir / p.texture->image.path, PixelEncoding::kLinear);
      const double mean = ScalarTextureMean(image, p.texture->factor, p.texture->offset);
      if (!ConstantAgrees(p.constant, mean)) NoteConstant(notes, kp + "/constant", Fmt(p.constant), Fmt(mean));
      p.constant = mean;
    }
    for (const ColorKey& key : ColorKeys()) {
      ColorParam& p = side->*key.member;
      if (!p.texture) continue;
      const std::string kp = sp + std::string(key.name);
      geometry(p.texture->image, kp + "/texture/image");
      if (!options.update_constants) continue;
      const Image image = ReadImageFile(base_dir / p.texture->image.path, PixelEncoding::kSrgb);
      const Rgb3 mean = ColorTextureMean(image, p.texture->mode, p.texture->factor);
      if (!ConstantAgrees(p.constant.r, mean.r) || !ConstantAgrees(p.constant.g, mean.g) || !ConstantAgrees(p.constant.b, mean.b))
        NoteConstant(notes, kp + "/constant", "(" + Fmt(p.constant.r) + ", " + Fmt(p.constant.g) + ", " + Fmt(p.constant.b) + ")",
                     "(" + Fmt(mean.r) + ", " + Fmt(mean.g) + ", " + Fmt(mean.b) + ")");
      p.constant = mean;
    }
    for (const NormalKey& key : NormalKeys()) {
      NormalParam& p = side->*key.member;
      if (!p.texture) continue;
      const std::string kp = sp + std::string(key.name);
      geometry(p.texture->image, kp + "/texture/image");
      if (!options.update_constants) continue;
      const Image image = ReadImageFile(base_dir / p.texture->image.path, PixelEncoding::kLinear);
      p.constant = NormalTextureMean(image, p.texture->scale);
    }
    if (side->preview && options.fix_image_geometry) {
      PreviewImage& pv = *side->preview;
      const ImageReadInfo info = ReadImageInfo(base_dir / pv.path);
      FixGeometry(pv.width_mm, pv.height_mm, pv.dpi_x, pv.dpi_y, info, false, sp + "preview", notes);
    }
  }
}

std::string WithSuffix(const std::string& path, int n) {
  const std::size_t slash = path.rfind('/');
  const std::size_t dot = path.rfind('.');
  const bool has_ext = dot != std::string::npos && (slash == std::string::npos || dot > slash + 1);
  const std::string stem = has_ext ? path.substr(0, dot) : path;
  return stem + "_" + std::to_string(n) + (has_ext ? path.substr(dot) : std::string());
}

struct PlannedFile {
  fs::path source;
  std::string dest;  // relative to the output folder
};

// Creates `dir` (and missing parents); unless Keep() is called, removes again what it created, so
// a failed save leaves no empty folders behind.
class CreatedFolder {
 public:
  explicit CreatedFolder(const fs::path& dir) {
    std::error_code ec;
    if (dir.empty() || fs::exists(dir, ec)) return;
    fs::path top = dir;
    while (top.has_parent_path() && top.parent_path() != top && !fs::exists(top.parent_path(), ec)) top = top.parent_path();
    fs::create_directories(dir, ec);
    if (ec) throw InputError(dir.string(), "", "expected a folder that can be created: " + ec.message());
    created_top_ = top;
  }
  ~CreatedFolder() {
    if (keep_ || created_top_.empty()) return;
    std::error_code ignored;
    fs::remove_all(created_top_, ignored);
  }
  void Keep() const { keep_ = true; }

 private:
  fs::path created_top_;
  mutable bool keep_ = false;
};

std::string PackageU3mName(const fs::path& out) {
  std::string name = SanitizeRelativePath(out.stem().string());
  if (name.find('/') != std::string::npos) name = "material";
  return name + ".u3m";
}

}  // namespace

bool PixelSizeAgrees(int pixels, double size_mm, double dpi) {
  const double expected = size_mm * dpi / kMmPerInch;
  return std::abs(pixels - expected) <= std::max(1.0, 0.02 * expected);
}

LoadedMaterial LoadMaterial(const fs::path& path) {
  LoadedMaterial loaded;
  loaded.source = path;
  if (IsU3m(path)) {
    loaded.u3m_name = path.filename().string();
    loaded.base_dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
    MaterialReadResult read = ReadMaterialJson(ReadText(path), path.string());
    loaded.material = std::move(read.material);
    loaded.version = read.version;
    loaded.issues = std::move(read.issues);
    return loaded;
  }
  if (!IsPackage(path)) throw InputError(path.string(), "", "expected a .u3m or .u3ma file");
  const fs::path unpacked = fs::temp_directory_path() / ("u3mscan-u3ma-" + RandomTag());
  std::vector<std::string> warnings;
  const std::vector<std::string> names = ExtractArchive(path, unpacked, {}, &warnings);
  // From here on the folder is ours: remove it with the last copy of the LoadedMaterial.
  loaded.unpacked_dir = std::shared_ptr<const fs::path>(new fs::path(unpacked), [](const fs::path* p) {
    std::error_code ignored;
    fs::remove_all(*p, ignored);
    delete p;
  });
  loaded.base_dir = unpacked;
  std::vector<std::string> roots;
  for (const std::string& name : names)
    if (name.find('/') == std::string::npos && IsU3m(name)) roots.push_back(name);
  if (roots.size() != 1)
    throw InputError(path.string(), "", "expected exactly one .u3m at the archive root, found " + std::to_string(roots.size()));
  loaded.u3m_name = roots.front();
  MaterialReadResult read = ReadMaterialJson(ReadText(unpacked / roots.front()), path.string() + ":" + roots.front());
  loaded.material = std::move(read.material);
  loaded.version = read.version;
  loaded.issues = std::move(read.issues);
  for (const std::string& warning : warnings) loaded.issues.push_back({IssueSeverity::kWarning, "", "archive: " + warning});
  return loaded;
}

SaveResult SaveMaterial(const Material& material, const fs::path& base_dir, const fs::path& out, const SaveOptions& options) {
  const std::string out_name = out.string();
  const bool package = IsPackage(out);
  if (!package && !IsU3m(out)) throw InputError(out_name, "", "expected an output name ending in .u3m or .u3ma");
  std::error_code ec;
  if (fs::exists(out, ec) && !options.overwrite)
    throw InputError(out_name, "", "expected an output that does not exist yet (--force replaces it)");

  SaveResult result;
  result.written = material;
  Material& m = result.written;

  // 1. Every referenced file must exist (or is dropped).
  std::vector<FileRef> refs = CollectFileRefs(m);
  std::vector<std::function<void()>> drops;
  for (const FileRef& ref : refs) {
    if (fs::is_regular_file(base_dir / *ref.path, ec)) continue;
    if (options.missing_files == MissingFiles::kRefuse)
      throw InputError(out_name, ref.pointer,
                       "expected the file \"" + *ref.path + "\" to exist in " + base_dir.string() +
                           " (--drop-missing writes the material without it)");
    result.notes.push_back({IssueSeverity::kWarning, ref.pointer, "file \"" + *ref.path + "\" not found; reference dropped"});
    drops.push_back(ref.drop);
  }
  for (const auto& drop : drops) drop();

  // 2. Sizes and constants from the textures themselves.
  UpdateFromTextures(m, base_dir, options, result.notes);
  if (options.update_modified) m.modified_ms = NowUtcMs();
  if (m.created_ms == 0) m.created_ms = m.modified_ms;

  // 3. Destination names: the same relative path where allowed, unique also without regard to case.
  const std::string u3m_name = package ? PackageU3mName(out) : out.filename().string();
  std::vector<PlannedFile> planned;
  std::map<std::string, std::string> dest_of_source;
  std::set<std::string> taken = {Lower(u3m_name)};
  for (FileRef& ref : CollectFileRefs(m)) {
    const fs::path source = base_dir / *ref.path;
    const std::string key = fs::weakly_canonical(source, ec).string();
    if (auto it = dest_of_source.find(key); it != dest_of_source.end()) {
      *ref.path = it->second;
      continue;
    }
    std::string dest = IsWritableRelativePath(*ref.path) ? *ref.path : SanitizeRelativePath(*ref.path);
    for (int n = 2; taken.count(Lower(dest)); ++n) dest = WithSuffix(IsWritableRelativePath(*ref.path) ? *ref.path : SanitizeRelativePath(*ref.path), n);
    if (dest != *ref.path)
      result.notes.push_back({IssueSeverity::kWarning, ref.pointer, "\"" + *ref.path + "\" written as \"" + dest + "\""});
    taken.insert(Lower(dest));
    dest_of_source[key] = dest;
    planned.push_back({source, dest});
    *ref.path = dest;
  }

  // 4. The text (refuses a version that cannot hold the content, and unwritable paths).
  MaterialWriteOptions write_options;
  write_options.version = options.version;
  MaterialWriteResult text = WriteMaterialJson(m, write_options, out_name);
  result.version = text.version;
  result.notes.insert(result.notes.end(), text.notes.begin(), text.notes.end());
  for (const PlannedFile& file : planned) result.files.push_back(file.dest);

  // 5. The files.
  if (package) {
    std::vector<ArchiveEntry> entries;
    entries.push_back({u3m_name, std::vector<std::uint8_t>(text.text.begin(), text.text.end())});
    for (const PlannedFile& file : planned) entries.push_back({file.dest, ReadBytes(file.source)});
    const CreatedFolder folder(out.parent_path());
    WriteArchive(out, entries);
    folder.Keep();
    return result;
  }

  const fs::path out_dir = out.parent_path().empty() ? fs::path(".") : out.parent_path();
  for (const PlannedFile& file : planned) {
    const fs::path final_path = out_dir / file.dest;
    if (fs::exists(final_path, ec) && !fs::equivalent(final_path, file.source, ec) && !options.overwrite)
      throw InputError(final_path.string(), "", "expected no existing file of this name (--force replaces it)");
  }
  const CreatedFolder folder(out_dir);
  const fs::path temp = out_dir / (".u3mscan-" + RandomTag() + ".partial");
  try {
    fs::create_directory(temp);
    std::vector<const PlannedFile*> moved;
    for (const PlannedFile& file : planned) {
      const fs::path final_path = out_dir / file.dest;
      if (fs::exists(final_path, ec) && fs::equivalent(final_path, file.source, ec)) continue;  // already in place
      const fs::path staged = temp / file.dest;
      fs::create_directories(staged.parent_path());
      fs::copy_file(file.source, staged, fs::copy_options::overwrite_existing);
      moved.push_back(&file);
    }
    WriteText(temp / u3m_name, text.text);
    // Textures first, the .u3m last: a reader never sees a .u3m whose files are not there yet.
    for (const PlannedFile* file : moved) {
      const fs::path final_path = out_dir / file->dest;
      fs::create_directories(final_path.parent_path());
      fs::rename(temp / file->dest, final_path);
    }
    fs::rename(temp / u3m_name, out);
  } catch (const fs::filesystem_error& e) {
    fs::remove_all(temp, ec);
    throw InputError(out_name, "", std::string("expected a writable output folder: ") + e.what());
  } catch (...) {
    fs::remove_all(temp, ec);
    throw;
  }
  fs::remove_all(temp, ec);
  folder.Keep();
  return result;
}

}  // namespace u3mscan

#include "capture/frame_decoder.h"

#include <libraw/libraw.h>

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/colour.h"
#include "core/error.h"
#include "core/parallel.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

// Demosaicing can spread one clipped photosite into its neighbours: AHD interpolates from a
// 5x5 neighbourhood, so a saturated photosite marks every pixel within this many pixels.
constexpr int kRawSaturationRadius = 2;
// Bytes read past the end of the file during unpacking before we call the file truncated.
// Bit-stream decoders may read a few bytes ahead at the end of the last strip.
constexpr long kTruncationSlackBytes = 1024;
// Rows converted per OIIO read; bounds the interleaved temporary to rows*width*channels floats.
constexpr int kRowsPerRead = 64;

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

void CheckDimensions(const fs::path& path, long long width, long long height) {
  if (width <= 0 || height <= 0 || width > kMaxFrameSide || height > kMaxFrameSide ||
      width * height > kMaxFramePixels) {
    throw InputError(path.string(), "",
                     "an image of at most " + std::to_string(kMaxFrameSide) + " pixels a side and " +
                         std::to_string(kMaxFramePixels / 1000000) + " megapixels, the header says " +
                         std::to_string(width) + "x" + std::to_string(height));
  }
}

void CheckRegion(const fs::path& path, int frame_w, int frame_h, int x, int y, int w, int h) {
  if (x < 0 || y < 0 || w <= 0 || h <= 0 || x > frame_w - w || y > frame_h - h) {
    throw std::out_of_range(path.string() + ": region " + std::to_string(x) + "," + std::to_string(y) + " " +
                            std::to_string(w) + "x" + std::to_string(h) + " is not inside the " +
                            std::to_string(frame_w) + "x" + std::to_string(frame_h) + " frame");
  }
}

// Marks every pixel within `radius` (Chebyshev distance) of a marked pixel: a row pass then a
// column pass, each a forward and a backward sweep, O(pixels) for any radius.
void Dilate(std::vector<std::uint8_t>* mask, int width, int height, int radius) {
  std::vector<std::uint8_t> tmp(mask->size(), 0);
  ParallelFor(static_cast<std::size_t>(height), [&](std::size_t begin, std::size_t end) {
    for (std::size_t r = begin; r < end; ++r) {
      const std::uint8_t* in = mask->data() + r * width;
      std::uint8_t* out = tmp.data() + r * width;
      // Distance to the nearest marked pixel on the left, then on the right.
      int last = -1 - radius * 2;
      for (int c = 0; c < width; ++c) {
        if (in[c]) last = c;
        if (c - last <= radius) out[c] = 1;
      }
      last = width + radius * 2;
      for (int c = width - 1; c >= 0; --c) {
        if (in[c]) last = c;
        if (last - c <= radius) out[c] = 1;
      }
    }
  });
  ParallelFor(static_cast<std::size_t>(width), [&](std::size_t begin, std::size_t end) {
    for (std::size_t c = begin; c < end; ++c) {
      int last = -1 - radius * 2;
      for (int r = 0; r < height; ++r) {
        const std::size_t i = static_cast<std::size_t>(r) * width + c;
        if (tmp[i]) last = r;
        (*mask)[i] = (r - last <= radius) ? 1 : 0;
      }
      last = height + radius * 2;
      for (int r = height - 1; r >= 0; --r) {
        const std::size_t i = static_cast<std::size_t>(r) * width + c;
        if (tmp[i]) last = r;
        if (last - r <= radius) (*mask)[i] = 1;
      }
    }
  });
}

// ---------------------------------------------------------------------------------------------
// libraw

// A file stream that counts what the decoder asked for past the end of the file: libraw's
// unpackers do not all report a truncated file, many fill the missing rows with zeros.
class CountingRawStream : public LibRaw_file_datastream {
 public:
  using LibRaw_file_datastream::LibRaw_file_datastream;
  int read(void* ptr, size_t size, size_t nmemb) override {
    const int got = LibRaw_file_datastream::read(ptr, size, nmemb);
    if (watching_ && got >= 0 && static_cast<size_t>(got) < nmemb) {
      missing_bytes_ += static_cast<long>((nmemb - got) * size);
    }
    return got;
  }
  int get_char() override {
    const int c = LibRaw_file_datastream::get_char();
    if (watching_ && c == EOF) ++missing_bytes_;
    return c;
  }
  void Watch() {
    watching_ = true;
    missing_bytes_ = 0;
  }
  long missing_bytes() const { return missing_bytes_; }

 private:
  bool watching_ = false;
  long missing_bytes_ = 0;
};

// Members in this order so the stream outlives the LibRaw object that reads from it.
struct RawSession {
  std::unique_ptr<CountingRawStream> stream;
  std::unique_ptr<LibRaw> raw = std::make_unique<LibRaw>(0);
};

[[noreturn]] void RawFail(const fs::path& path, const std::string& what, int code) {
  throw InputError(path.string(), "", what + " (libraw: " + libraw_strerror(code) + ")");
}

// Opens and parses the metadata; no pixel data is read.
void OpenRaw(const fs::path& path, const FrameDecodeOptions& options, RawSession* s) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw InputError(path.string(), "", "an existing RAW image file");
  s->stream = std::make_unique<CountingRawStream>(path.c_str());
  if (!s->stream->valid()) throw InputError(path.string(), "", "a readable RAW image file");
  libraw_output_params_t& p = s->raw->imgdata.params;
  p.output_bps = 16;
  p.gamm[0] = 1.0;  // linear: no transfer curve
  p.gamm[1] = 1.0;
  p.no_auto_bright = 1;
  p.user_qual = 3;             // AHD demosaic
  p.highlight = 1;             // unclipped: white balance must not clip channels, see DecodeRaw
  p.adjust_maximum_thr = 0.0f; // keep the file's white level, never the data maximum
  p.user_flip = 0;             // sensor orientation: pixels must match the camera intrinsics
  p.use_fuji_rotate = 0;       // no 45-degree Fuji rotation, no pixel-aspect stretch
  p.output_color = 1;          // linear sRGB primaries
  if (options.white_balance) {
    p.use_camera_wb = 0;
    const auto& m = *options.white_balance;
    p.user_mul[0] = static_cast<float>(m[0]);
    p.user_mul[1] = static_cast<float>(m[1]);
    p.user_mul[2] = static_cast<float>(m[2]);
    p.user_mul[3] = static_cast<float>(m[1]);
  } else {
    p.use_camera_wb = 1;
  }
  if (options.response) {
    // libraw 0.20 takes user_sat as the white level above the (subtracted) black level: with
    // user_sat set it scales by 65535 / user_sat, not 65535 / (user_sat - black).
    // The manifest's black level replaces the file's, per-channel offsets included.
    p.user_black = static_cast<int>(std::lround(options.response->black_level));
    for (int c = 0; c < 4; ++c) p.user_cblack[c] = 0;
    p.user_sat = static_cast<int>(std::lround(options.response->white_level - options.response->black_level));
  }
  const int rc = s->raw->open_datastream(s->stream.get());
  if (rc != LIBRAW_SUCCESS) RawFail(path, "a RAW image file that libraw reads", rc);
  const auto& sz = s->raw->imgdata.sizes;
  CheckDimensions(path, sz.raw_width, sz.raw_height);
  CheckDimensions(path, sz.width, sz.height);
}

CompactFrame DecodeRaw(const fs::path& path, const FrameDecodeOptions& options) {
  RawSession s;
  OpenRaw(path, options, &s);
  LibRaw& raw = *s.raw;
  s.stream->Watch();
  int rc = raw.unpack();
  if (rc != LIBRAW_SUCCESS) RawFail(path, "complete RAW image data (truncated or corrupt?)", rc);
  if (s.stream->missing_bytes() > kTruncationSlackBytes) {
    throw InputError(path.string(), "",
                     "complete RAW image data; the file ends " + std::to_string(s.stream->missing_bytes()) +
                         " bytes early (truncated)");
  }

  const auto& sz = raw.imgdata.sizes;
  const int width = sz.width, height = sz.height;
  CompactFrame out;
  out.width = width;
  out.height = height;
  out.saturated.assign(static_cast<std::size_t>(width) * height, 0);

  // Saturation from the sensor values before anything scales or interpolates them.
  const unsigned white = options.response ? static_cast<unsigned>(std::lround(options.response->white_level))
                                          : raw.imgdata.color.maximum;
  const auto& rd = raw.imgdata.rawdata;
  const int top = sz.top_margin, left = sz.left_margin;
  if (rd.raw_image) {
    const std::size_t pitch = sz.raw_pitch / sizeof(unsigned short);
    for (int r = 0; r < height && r + top < sz.raw_height; ++r) {
      const unsigned short* row = rd.raw_image + static_cast<std::size_t>(r + top) * pitch + left;
      std::uint8_t* m = out.saturated.data() + static_cast<std::size_t>(r) * width;
      for (int c = 0; c < width && c + left < sz.raw_width; ++c) m[c] = row[c] >= white ? 1 : 0;
    }
    Dilate(&out.saturated, width, height, kRawSaturationRadius);
  } else if (rd.color4_image || rd.color3_image) {
    const int channels = rd.color4_image ? 4 : 3;
    const std::size_t pitch = sz.raw_pitch / sizeof(unsigned short);
    const unsigned short* base = rd.color4_image ? &rd.color4_image[0][0] : &rd.color3_image[0][0];
    for (int r = 0; r < height && r + top < sz.raw_height; ++r) {
      const unsigned short* row = base + static_cast<std::size_t>(r + top) * pitch + static_cast<std::size_t>(left) * channels;
      std::uint8_t* m = out.saturated.data() + static_cast<std::size_t>(r) * width;
      for (int c = 0; c < width && c + left < sz.raw_width; ++c) {
        for (int k = 0; k < std::min(channels, 3); ++k) {
          if (row[c * channels + k] >= white) m[c] = 1;
        }
      }
    }
  } else {
    throw InputError(path.string(), "", "a RAW image with Bayer or RGB sensor data (this layout is not supported)");
  }

  rc = raw.dcraw_process();
  if (rc != LIBRAW_SUCCESS) RawFail(path, "a RAW image libraw can process", rc);
  int err = 0;
  libraw_processed_image_t* img = raw.dcraw_make_mem_image(&err);
  if (!img) RawFail(path, "a RAW image libraw can process", err);
  std::unique_ptr<libraw_processed_image_t, void (*)(libraw_processed_image_t*)> guard(img, LibRaw::dcraw_clear_mem);
  if (img->type != LIBRAW_IMAGE_BITMAP || img->bits != 16 || img->colors != 3 || img->width != width ||
      img->height != height) {
    throw InputError(path.string(), "",
                     "a RAW image that decodes to " + std::to_string(width) + "x" + std::to_string(height) +
                         " 16-bit RGB (this sensor layout is not supported)");
  }
  out.rgb16.resize(static_cast<std::size_t>(width) * height * 3);
  std::copy_n(reinterpret_cast<const std::uint16_t*>(img->data), out.rgb16.size(), out.rgb16.data());
  // libraw clips its output at 65535; a colour matrix with gains above 1 can get there from
  // unsaturated photosites near the white level. A clipped value is not data either.
  ParallelFor(static_cast<std::size_t>(height), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b * width; i < e * width; ++i) {
      const std::uint16_t* px = out.rgb16.data() + i * 3;
      if (px[0] == 65535 || px[1] == 65535 || px[2] == 65535) out.saturated[i] = 1;
    }
  });

  // libraw scaled by pre_mul / max(pre_mul) so that no channel clips (highlight = 1); undo the
  // division by the largest so the reference channel (smallest multiplier) has 1.0 = white level.
  const auto& pre_mul = raw.imgdata.color.pre_mul;
  float min_mul = 1.0f;
  for (int c = 0; c < std::max(3, static_cast<int>(raw.imgdata.idata.colors)) && c < 4; ++c) {
    if (pre_mul[c] > 0.0f) min_mul = std::min(min_mul, pre_mul[c]);
  }
  out.scale = 1.0f / (65535.0f * min_mul);
  return out;
}

// ---------------------------------------------------------------------------------------------
// OpenImageIO

struct OiioLayout {
  FrameEncoding encoding = FrameEncoding::kLinear;
  double code_max = 1.0;  // OIIO float = code / code_max for integer files
};

OiioLayout LayoutOf(const fs::path& path, const OIIO::ImageSpec& spec) {
  OiioLayout l;
  const OIIO::TypeDesc t = spec.format;
  if (t == OIIO::TypeDesc::UINT8) {
    l.encoding = FrameEncoding::kSrgb;
    l.code_max = 255.0;
  } else if (t == OIIO::TypeDesc::UINT16) {
    l.code_max = 65535.0;
  } else if (t == OIIO::TypeDesc::HALF || t == OIIO::TypeDesc::FLOAT || t == OIIO::TypeDesc::DOUBLE) {
    l.code_max = 1.0;
  } else {
    throw InputError(path.string(), "", "an 8-bit, 16-bit or floating-point image, the file holds " + std::string(t.c_str()));
  }
  if (spec.nchannels < 1) throw InputError(path.string(), "", "an image with at least one channel");
  return l;
}

std::unique_ptr<OIIO::ImageInput> OpenOiio(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw InputError(path.string(), "", "an existing image file");
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) {
    throw InputError(path.string(), "", "a readable image (16-bit TIFF/PNG, EXR, 8-bit JPEG/PNG): " + OIIO::geterror());
  }
  const auto& spec = in->spec();
  CheckDimensions(path, spec.width, spec.height);
  return in;
}

// JPEG decoders fill a truncated file with grey and only warn; the end-of-image marker is the
// cheap, certain test.
void CheckJpegComplete(const fs::path& path) {
  const std::string ext = Lower(path.extension().string());
  if (ext != ".jpg" && ext != ".jpeg") return;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw InputError(path.string(), "", "a readable JPEG file");
  unsigned char tail[2] = {0, 0};
  const bool ok = std::fseek(f, -2, SEEK_END) == 0 && std::fread(tail, 1, 2, f) == 2;
  std::fclose(f);
  if (!ok || tail[0] != 0xFF || tail[1] != 0xD9) {
    throw InputError(path.string(), "", "a complete JPEG file (it does not end with the end-of-image marker; truncated?)");
  }
}

// A read of rows or tiles that returned `ok`: InputError naming the file unless it is complete.
// OIIO's TIFF reader reports a short strip as an error message but still returns true.
void CheckRead(OIIO::ImageInput& in, const fs::path& path, bool ok) {
  if (!ok || in.has_error()) {
    throw InputError(path.string(), "", "complete image data (truncated or corrupt?): " + in.geterror());
  }
}

// How a value OIIO delivers as float (code / code_max for integer files) becomes linear data, and
// whether it is at the white level. One rule for region reads and for the code tables of
// CompactFrame (DecodeOiioCompact), so both give the same floats to the bit.
struct OiioValueRule {
  FrameEncoding encoding = FrameEncoding::kLinear;
  bool has_white = true;
  float black = 0.0f, white = 1.0f, inv_range = 1.0f;
  // For 8-bit data the file's top code is the white level.
  static constexpr float kSrgbWhite = 254.5f / 255.0f;

  OiioValueRule(const OiioLayout& layout, const OIIO::ImageSpec& spec, const FrameDecodeOptions& options)
      : encoding(layout.encoding) {
    // Response: levels in code values, applied to linear data only.
    double black_code = 0.0, white_code = layout.code_max;
    if (layout.encoding == FrameEncoding::kLinear && options.response) {
      black_code = options.response->black_level;
      white_code = options.response->white_level;
    }
    const bool float_file = layout.code_max == 1.0 && spec.format != OIIO::TypeDesc::UINT8;
    // Float files without a response have no white level: nothing saturates but non-finite values.
    has_white = !(float_file && !options.response);
    inv_range = static_cast<float>(layout.code_max / (white_code - black_code));
    black = static_cast<float>(black_code / layout.code_max);
    white = static_cast<float>(white_code / layout.code_max);
  }

  // Linear value of file value v; sets *saturated when v is not data.
  float Linear(float v, bool* saturated) const {
    if (!std::isfinite(v)) {
      *saturated = true;
      return 0.0f;
    }
    if (encoding == FrameEncoding::kSrgb) {
      *saturated = *saturated || v >= kSrgbWhite;
      return SrgbToLinear(v);
    }
    *saturated = *saturated || (has_white && v >= white);
    return (v - black) * inv_range;
  }
};

DecodedFrame DecodeOiioRegion(const fs::path& path, const FrameDecodeOptions& options, int x, int y, int w, int h,
                              bool whole) {
  auto in = OpenOiio(path);
  const OIIO::ImageSpec spec = in->spec();
  const OiioLayout layout = LayoutOf(path, spec);
  if (whole) {
    x = 0;
    y = 0;
    w = spec.width;
    h = spec.height;
  }
  CheckRegion(path, spec.width, spec.height, x, y, w, h);
  CheckJpegComplete(path);

  DecodedFrame out;
  out.encoding = layout.encoding;
  out.rgb = Image(w, h, 3);
  out.saturated.assign(static_cast<std::size_t>(w) * h, 0);
  const OiioValueRule rule(layout, spec, options);

  const int nch = spec.nchannels;
  // Scanline files are read in bands of kRowsPerRead full rows; tiled files one row of tiles at
  // a time, only the tile columns the region touches (read_tiles needs tile-aligned bounds).
  const bool tiled = spec.tile_width > 0 && spec.tile_height > 0;
  const int band_rows = tiled ? spec.tile_height : kRowsPerRead;
  const int buf_x0 = tiled ? x / spec.tile_width * spec.tile_width : 0;
  const int buf_x1 =
      tiled ? std::min(spec.width, (x + w + spec.tile_width - 1) / spec.tile_width * spec.tile_width) : spec.width;
  const int buf_w = buf_x1 - buf_x0;
  const int read_y0 = tiled ? y / spec.tile_height * spec.tile_height : y;
  const int read_y1 = y + h;
  std::vector<float> buffer;
  for (int band = read_y0; band < read_y1; band += band_rows) {
    const int band_end = tiled ? std::min(spec.height, band + band_rows) : std::min(read_y1, band + band_rows);
    buffer.resize(static_cast<std::size_t>(band_end - band) * buf_w * nch);
    bool ok;
    if (tiled) {
      ok = in->read_tiles(0, 0, spec.x + buf_x0, spec.x + buf_x1, spec.y + band, spec.y + band_end, spec.z,
                          spec.z + std::max(1, spec.depth), 0, nch, OIIO::TypeDesc::FLOAT, buffer.data());
    } else {
      ok = in->read_scanlines(0, 0, spec.y + band, spec.y + band_end, 0, 0, nch, OIIO::TypeDesc::FLOAT, buffer.data());
    }
    CheckRead(*in, path, ok);
    const int row_begin = std::max(band, y), row_end = std::min(band_end, y + h);
    ParallelFor(static_cast<std::size_t>(std::max(0, row_end - row_begin)), [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        const int row = row_begin + static_cast<int>(i);
        const float* src = buffer.data() + (static_cast<std::size_t>(row - band) * buf_w + (x - buf_x0)) * nch;
        const int out_row = row - y;
        std::uint8_t* sat = out.saturated.data() + static_cast<std::size_t>(out_row) * w;
        for (int c = 0; c < w; ++c) {
          const float* px = src + static_cast<std::size_t>(c) * nch;
          bool saturated = false;
          // Grey files feed all three channels.
          for (int k = 0; k < 3; ++k) out.rgb.at(k, out_row, c) = rule.Linear(px[nch >= 3 ? k : 0], &saturated);
          sat[c] = saturated ? 1 : 0;
        }
      }
    });
  }
  in->close();
  return out;
}

// An 8- or 16-bit scanline frame (TIFF, PNG, JPEG) whole, as its code values (16 bits a channel,
// 8-bit codes widened) and a table from code to linear value built with the rule and OIIO's own
// conversion to float, so a crop equals DecodeOiioRegion's read of the same rows to the bit. Read
// top to bottom in bands of kRowsPerRead rows (PNG and JPEG decode from the top: one pass costs
// what a read of the last rows costs).
CompactFrame DecodeOiioCompact(const fs::path& path, const FrameDecodeOptions& options) {
  auto in = OpenOiio(path);
  const OIIO::ImageSpec spec = in->spec();
  const OiioLayout layout = LayoutOf(path, spec);
  if (spec.format != OIIO::TypeDesc::UINT8 && spec.format != OIIO::TypeDesc::UINT16) {
    throw std::invalid_argument(path.string() + ": a compact frame holds 8- or 16-bit codes, the file holds " +
                                std::string(spec.format.c_str()));
  }
  if (spec.tile_width > 0 && spec.tile_height > 0) {
    throw std::invalid_argument(path.string() + ": a compact frame is read by scanlines, the file is tiled");
  }
  CheckJpegComplete(path);
  const OiioValueRule rule(layout, spec, options);
  const int codes = static_cast<int>(layout.code_max) + 1;
  CompactFrame out;
  out.width = spec.width;
  out.height = spec.height;
  out.encoding = layout.encoding;
  out.linear_of_code.resize(codes);
  std::vector<std::uint8_t> saturated_code(codes, 0);
  for (int code = 0; code < codes; ++code) {
    const std::uint16_t code16 = static_cast<std::uint16_t>(code);
    const std::uint8_t code8 = static_cast<std::uint8_t>(code);
    float v = 0.0f;
    OIIO::convert_pixel_values(spec.format, spec.format == OIIO::TypeDesc::UINT8 ? static_cast<const void*>(&code8) : &code16,
                               OIIO::TypeDesc::FLOAT, &v, 1);
    bool saturated = false;
    out.linear_of_code[code] = rule.Linear(v, &saturated);
    saturated_code[code] = saturated ? 1 : 0;
  }
  const std::size_t pixels = static_cast<std::size_t>(out.width) * out.height;
  out.rgb16.resize(pixels * 3);
  out.saturated.assign(pixels, 0);
  const int nch = spec.nchannels;
  const bool bytes = spec.format == OIIO::TypeDesc::UINT8;
  // The file's own codes, read as stored (no conversion).
  std::vector<std::uint8_t> buffer8;
  std::vector<std::uint16_t> buffer16;
  for (int band = 0; band < spec.height; band += kRowsPerRead) {
    const int band_end = std::min(spec.height, band + kRowsPerRead);
    const std::size_t values = static_cast<std::size_t>(band_end - band) * spec.width * nch;
    void* data = nullptr;
    if (bytes) {
      buffer8.resize(values);
      data = buffer8.data();
    } else {
      buffer16.resize(values);
      data = buffer16.data();
    }
    CheckRead(*in, path, in->read_scanlines(0, 0, spec.y + band, spec.y + band_end, 0, 0, nch, spec.format, data));
    ParallelFor(static_cast<std::size_t>(band_end - band), [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        const std::size_t row = static_cast<std::size_t>(band) + i;
        for (int c = 0; c < spec.width; ++c) {
          const std::size_t p = row * spec.width + c;
          const std::size_t src = (i * spec.width + c) * nch;
          std::uint8_t saturated = 0;
          for (int k = 0; k < 3; ++k) {
            const std::size_t at = src + (nch >= 3 ? k : 0);  // grey files feed all three channels
            const std::uint16_t code = bytes ? buffer8[at] : buffer16[at];
            out.rgb16[p * 3 + k] = code;
            saturated |= saturated_code[code];
          }
          out.saturated[p] = saturated;
        }
      }
    });
  }
  in->close();
  return out;
}

}  // namespace

bool IsRawPath(const fs::path& path) {
  const std::string ext = Lower(path.extension().string());
  return !(ext == ".tif" || ext == ".tiff" || ext == ".png" || ext == ".exr" || ext == ".jpg" || ext == ".jpeg");
}

FrameHeader ReadFrameHeader(const fs::path& path) {
  FrameHeader header;
  if (IsRawPath(path)) {
    RawSession s;
    OpenRaw(path, {}, &s);
    header.width = s.raw->imgdata.sizes.width;
    header.height = s.raw->imgdata.sizes.height;
    header.encoding = FrameEncoding::kRaw;
    header.keep_whole = true;
    return header;
  }
  auto in = OpenOiio(path);
  const OIIO::ImageSpec& spec = in->spec();
  header.width = spec.width;
  header.height = spec.height;
  header.encoding = LayoutOf(path, spec).encoding;
  const std::string ext = Lower(path.extension().string());
  const bool codes = spec.format == OIIO::TypeDesc::UINT8 || spec.format == OIIO::TypeDesc::UINT16;
  const bool tiled = spec.tile_width > 0 && spec.tile_height > 0;
  const bool from_the_top = ext == ".png" || ext == ".jpg" || ext == ".jpeg";
  const bool compressed_tiff =
      (ext == ".tif" || ext == ".tiff") && spec.get_string_attribute("compression", "none") != "none";
  header.keep_whole = codes && !tiled && (from_the_top || compressed_tiff);
  return header;
}

DecodedFrame CompactFrame::Crop(int x, int y, int w, int h) const {
  CheckRegion("frame", width, height, x, y, w, h);
  DecodedFrame out;
  out.encoding = encoding;
  out.rgb = Image(w, h, 3);
  out.saturated.resize(static_cast<std::size_t>(w) * h);
  const bool table = !linear_of_code.empty();
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t b, std::size_t e) {
    for (std::size_t r = b; r < e; ++r) {
      const std::size_t src_row = static_cast<std::size_t>(y) + r;
      const std::uint16_t* src = rgb16.data() + (src_row * width + x) * 3;
      for (int c = 0; c < w; ++c) {
        for (int k = 0; k < 3; ++k) {
          const std::uint16_t code = src[c * 3 + k];
          out.rgb.at(k, static_cast<int>(r), c) = table ? linear_of_code[code] : code * scale;
        }
      }
      std::copy_n(saturated.data() + src_row * width + x, w, out.saturated.data() + r * w);
    }
  });
  return out;
}

CompactFrame DecodeWholeFrame(const fs::path& path, const FrameDecodeOptions& options) {
  return IsRawPath(path) ? DecodeRaw(path, options) : DecodeOiioCompact(path, options);
}

DecodedFrame DecodeFrame(const fs::path& path, const FrameDecodeOptions& options) {
  if (IsRawPath(path)) {
    const CompactFrame compact = DecodeRaw(path, options);
    return compact.Crop(0, 0, compact.width, compact.height);
  }
  return DecodeOiioRegion(path, options, 0, 0, 0, 0, true);
}

DecodedFrame DecodeFrameRegion(const fs::path& path, const FrameDecodeOptions& options, int x, int y, int w, int h) {
  if (IsRawPath(path)) {
    const CompactFrame compact = DecodeRaw(path, options);
    CheckRegion(path, compact.width, compact.height, x, y, w, h);
    return compact.Crop(x, y, w, h);
  }
  return DecodeOiioRegion(path, options, x, y, w, h, false);
}

}  // namespace u3mscan

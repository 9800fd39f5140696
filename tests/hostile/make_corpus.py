#!/usr/bin/python3
"""Writes the checked-in corpus of bad inputs (tests/hostile/{u3m,u3ma,manifest,images}/).

Deterministic; run it from anywhere to regenerate: /usr/bin/python3 tests/hostile/make_corpus.py
SOURCE_IMAGES: a folder with g16.png (32x32 RGB 16-bit), g16.tif (zip), g.exr (half, zip) and
g8.jpg, made with OpenImageIO's oiiotool:
  oiiotool --pattern fill:topleft=0.1,0.2,0.3:topright=0.5,0.4,0.3:bottomleft=0.2,0.6,0.1:bottomright=0.7,0.7,0.7 \
    32x32 3 -d uint16 -o g16.png
  oiiotool g16.png -d uint16 --compression zip -o g16.tif
  oiiotool g16.png -d half --compression zip -o g.exr
  oiiotool g16.png -d uint8 --quality 80 -o g8.jpg
Large inputs (deep nesting, the zip bomb, the DNG cases) are made by hostile_test.cc itself.
"""
import io
import json
import os
import random
import struct
import sys
import zipfile
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
SRC = sys.argv[1] if len(sys.argv) > 1 else "/tmp"


def out(sub, name, data):
    os.makedirs(os.path.join(HERE, sub), exist_ok=True)
    if isinstance(data, str):
        data = data.encode("utf-8")
    with open(os.path.join(HERE, sub, name), "wb") as f:
        f.write(data)


# ---------------------------------------------------------------- U3M (texture-free base, 1.1)
def _base_u3m():
    # The example 1.1 material of `u3mscan example` (tests/fuzz/corpus) without its files.
    with open(os.path.join(HERE, "..", "fuzz", "corpus", "u3m_json", "example_1_1.u3m")) as f:
        doc = json.load(f)
    m = doc["material"]
    m["id"] = "3f0c1b2e-8d4a-4f6b-9c1d-2e3f4a5b6c7d"
    m["name"] = "hostile base"
    m["created"] = m["modified"] = "2024-01-01T00:00:00Z"
    for side in ("front", "back", "side"):
        if not isinstance(m.get(side), dict):
            continue
        for key, param in m[side].items():
            if isinstance(param, dict) and "texture" in param:
                param["texture"] = None
        m[side]["preview"] = None
        m[side]["roughness"]["constant"] = 0.7
    if isinstance(m.get("physics"), dict):
        m["physics"]["devices"] = {"fab": "null"}
    return doc


BASE_U3M = _base_u3m()


def u3m_text(doc):
    return json.dumps(doc, indent=1)


def with_texture(path):
    doc = json.loads(json.dumps(BASE_U3M))
    doc["material"]["front"]["basecolor"]["texture"] = {
        "mode": "multiply", "factor": {"r": 1, "g": 1, "b": 1},
        "image": {"path": path, "width": 3.2, "height": 3.2, "dpi": {"x": 254, "y": 254},
                  "repeat": {"rotation": 0, "mode": "normal"}}}
    return doc


base = u3m_text(BASE_U3M)
out("u3m", "base_valid.u3m", base)  # the control: must be valid
out("u3m", "texture_base.u3m", u3m_text(with_texture("textures/basecolor.png")))  # + a bad image beside it
out("u3m", "truncated.u3m", base[: len(base) // 2])
out("u3m", "empty.u3m", b"")
rng = random.Random(8)
out("u3m", "binary_garbage.u3m", bytes(rng.randrange(256) for _ in range(512)))
out("u3m", "not_an_object.u3m", "[1, 2, 3]\n")
out("u3m", "wrong_type_name.u3m", base.replace('"hostile base"', "42"))
out("u3m", "wrong_type_constant.u3m", base.replace('"constant": 0.7', '"constant": "0.7"'))
out("u3m", "wrong_type_front.u3m", u3m_text({**BASE_U3M, "material": {**BASE_U3M["material"], "front": [1, 2]}}))
out("u3m", "nan_token.u3m", base.replace('"constant": 0.7', '"constant": NaN'))
out("u3m", "infinity_token.u3m", base.replace('"constant": 0.7', '"constant": -Infinity'))
out("u3m", "huge_number.u3m", base.replace('"constant": 0.7', '"constant": 1e400'))
out("u3m", "big_number.u3m", base.replace('"constant": 0.7', '"constant": 1e300'))
out("u3m", "duplicate_keys.u3m", base.replace('"name": "hostile base"', '"name": "hostile base", "name": "again"'))
out("u3m", "unknown_schema.u3m", base.replace('"schema": "1.1"', '"schema": "2.0"'))
out("u3m", "bad_timestamp.u3m", base.replace('"created": "2024-01-01T00:00:00Z"', '"created": "yesterday"'))
out("u3m", "invalid_utf8.u3m", base.encode().replace(b"hostile base", b"hostile \xff\xfe base"))
out("u3m", "traversal_texture.u3m", u3m_text(with_texture("../../../etc/passwd")))
out("u3m", "absolute_texture.u3m", u3m_text(with_texture("/etc/passwd")))
out("u3m", "drive_texture.u3m", u3m_text(with_texture("C:/Windows/win.ini")))
out("u3m", "backslash_traversal_texture.u3m", u3m_text(with_texture("textures\\..\\..\\..\\etc\\passwd")))


# ---------------------------------------------------------------- .u3ma (restricted ZIP)
T = (2024, 1, 1, 0, 0, 0)


def zip_of(entries, tweak=None):
    """entries: (name, bytes, method, external_attr); tweak(ZipInfo) may edit a header."""
    b = io.BytesIO()
    with zipfile.ZipFile(b, "w") as z:
        for name, data, method, attr in entries:
            zi = zipfile.ZipInfo(name, T)
            zi.compress_type = method
            zi.external_attr = attr
            z.writestr(zi, data)
    return b.getvalue()


S, D = zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED
mat = base.encode()
good = zip_of([("material.u3m", mat, D, 0)])
out("u3ma", "not_a_zip.u3ma", "this is a text file, not a zip archive\n")
out("u3ma", "empty.u3ma", b"")
out("u3ma", "truncated.u3ma", good[: len(good) // 2])
out("u3ma", "traversal_entry.u3ma", zip_of([("material.u3m", mat, D, 0), ("../evil.png", b"evil", S, 0)]))
out("u3ma", "absolute_entry.u3ma", zip_of([("material.u3m", mat, D, 0), ("/tmp/u3mscan_hostile_evil.png", b"evil", S, 0)]))
out("u3ma", "backslash_entry.u3ma", zip_of([("material.u3m", mat, D, 0), ("..\\evil.png", b"evil", S, 0)]))
import warnings
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    out("u3ma", "duplicate_entry.u3ma", zip_of([("material.u3m", mat, D, 0), ("material.u3m", mat, D, 0)]))
out("u3ma", "symlink_entry.u3ma", zip_of([("material.u3m", mat, D, 0), ("textures/link.png", b"/etc/passwd", S, 0xA1FF << 16)]))
out("u3ma", "no_material.u3ma", zip_of([("textures/a.png", b"\x89PNG", S, 0)]))
out("u3ma", "two_materials.u3ma", zip_of([("a.u3m", mat, D, 0), ("b.u3m", mat, D, 0)]))
out("u3ma", "bad_material.u3ma", zip_of([("material.u3m", base.replace('"constant": 0.7', '"constant": NaN').encode(), D, 0)]))
out("u3ma", "traversal_texture.u3ma", zip_of([("material.u3m", u3m_text(with_texture("../../evil.png")).encode(), D, 0)]))
# Local and central headers claim 256 MiB uncompressed for a 1-byte stored entry.
lie = bytearray(zip_of([("material.u3m", mat, S, 0)]))
i = lie.find(b"PK\x03\x04"); struct.pack_into("<I", lie, i + 22, 0x10000000)
i = lie.find(b"PK\x01\x02"); struct.pack_into("<I", lie, i + 24, 0x10000000)
out("u3ma", "sizes_lie.u3ma", bytes(lie))
# General-purpose flag bit 0: encrypted.
enc = bytearray(good)
i = enc.find(b"PK\x03\x04"); struct.pack_into("<H", enc, i + 6, 1)
i = enc.find(b"PK\x01\x02"); struct.pack_into("<H", enc, i + 8, 1)
out("u3ma", "encrypted.u3ma", bytes(enc))
# Overlapping entries: two central records point at the same local header (the "non-recursive
# zip bomb" shape, tiny here).
ov = bytearray(zip_of([("material.u3m", mat, D, 0), ("copy.u3m", mat, D, 0)]))
c1 = ov.find(b"PK\x01\x02"); c2 = ov.find(b"PK\x01\x02", c1 + 4)
off1 = struct.unpack_from("<I", ov, c1 + 42)[0]
struct.pack_into("<I", ov, c2 + 42, off1)
out("u3ma", "overlapping_entries.u3ma", bytes(ov))


# ---------------------------------------------------------------- capture manifests
MANIFEST = {
    "format": "u3m-capture/1",
    "scanner": {"vendor": "Acme", "model": "LightDome 1", "serial": "SN-1", "software": "acquire 2.0"},
    "sample": {"name": "hostile", "description": "bad-input tests"},
    "cameras": [{"id": "top", "width": 32, "height": 32,
                 "intrinsics": {"fx": 100.0, "fy": 100.0, "cx": 15.5, "cy": 15.5},
                 "distortion": [0, 0, 0, 0, 0],
                 "pose": {"rotation": [[1, 0, 0], [0, -1, 0], [0, 0, -1]], "translation_mm": [0, 0, 500]}}],
    "lights": [
        {"id": "L0", "type": "directional", "direction": [0.6, 0.0, 0.8], "intensity": [1.0, 1.0, 1.0]},
        {"id": "L1", "type": "directional", "direction": [-0.6, 0.0, 0.8], "intensity": [1.0, 1.0, 1.0]}],
    "frames": [
        {"file": "frames/sample_0.png", "camera": "top", "light": "L0", "exposure_s": 0.01, "role": "sample"},
        {"file": "frames/sample_1.png", "camera": "top", "light": "L1", "exposure_s": 0.01, "role": "sample"},
        {"file": "frames/dark.png", "camera": "top", "light": None, "exposure_s": 0.01, "role": "dark"}],
}


def manifest(mutate=None):
    doc = json.loads(json.dumps(MANIFEST))
    if mutate:
        mutate(doc)
    return json.dumps(doc, indent=1)


def setter(path, value):
    def f(doc):
        node = doc
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return f


m = manifest()
out("manifest", "valid.json", m)  # the control: the test writes its frames
out("manifest", "truncated.json", m[: len(m) // 2])
out("manifest", "not_json.json", "format: u3m-capture/1\n")
out("manifest", "nan_token.json", m.replace('"exposure_s": 0.01', '"exposure_s": NaN', 1))
out("manifest", "infinity_token.json", m.replace('"exposure_s": 0.01', '"exposure_s": Infinity', 1))
out("manifest", "huge_number.json", m.replace('"exposure_s": 0.01', '"exposure_s": 1e400', 1))
out("manifest", "duplicate_keys.json", m.replace('"format": "u3m-capture/1"', '"format": "u3m-capture/1", "format": "u3m-capture/1"'))
out("manifest", "wrong_type_width.json", manifest(setter(["cameras", 0, "width"], "32")))
out("manifest", "wrong_type_frames.json", manifest(setter(["frames"], {"file": "frames/sample_0.png"})))
out("manifest", "negative_exposure.json", manifest(setter(["frames", 0, "exposure_s"], -0.5)))
out("manifest", "enormous_camera.json", manifest(setter(["cameras", 0, "width"], 1000000000)))
out("manifest", "traversal_frame.json", manifest(setter(["frames", 0, "file"], "../outside.png")))
out("manifest", "absolute_frame.json", manifest(setter(["frames", 0, "file"], "/etc/passwd")))
out("manifest", "backslash_frame.json", manifest(setter(["frames", 0, "file"], "frames\\..\\..\\outside.png")))
out("manifest", "missing_frame.json", manifest(setter(["frames", 0, "file"], "frames/not_there.png")))
out("manifest", "unknown_light.json", manifest(setter(["frames", 0, "light"], "L9")))

# ---------------------------------------------------------------- images (frames and textures)
def read(name):
    with open(os.path.join(SRC, name), "rb") as f:
        return f.read()


def png_chunk(kind, payload):
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload) & 0xFFFFFFFF)


png = read("g16.png")
out("images", "truncated_after_header.png", png[:120])  # signature + IHDR intact, data cut
bad = bytearray(png)
idat = bad.find(b"IDAT")
for k in range(idat + 8, min(len(bad) - 16, idat + 400), 7):
    bad[k] ^= 0x5A  # corrupt the compressed stream (CRC no longer matches)
out("images", "corrupt_data.png", bytes(bad))
# Valid signature and IHDR (CRC correct) claiming 65536 x 65536 16-bit RGB, then one tiny IDAT.
ihdr = struct.pack(">IIBBBBB", 65536, 65536, 16, 2, 0, 0, 0)
huge = b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", zlib.compress(b"\x00" * 64)) + png_chunk(b"IEND", b"")
out("images", "enormous_dimensions.png", huge)
# 36000 x 36000 RGB 8-bit: under the 2^32-sample cap of u3m/image_io, 15 GB as float.
ihdr = struct.pack(">IIBBBBB", 36000, 36000, 8, 2, 0, 0, 0)
out("images", "large_dimensions.png",
    b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", zlib.compress(b"\x00" * 64)) + png_chunk(b"IEND", b""))
out("images", "text.png", "not an image\n")
tif = read("g16.tif")
out("images", "truncated.tif", tif[: len(tif) // 3])
bad = bytearray(tif)
for k in range(16, len(bad) - 16, 5):
    bad[k] ^= 0xA5  # offsets, counts and data all garbage
out("images", "corrupt.tif", bytes(bad))
exr = read("g.exr")
out("images", "truncated.exr", exr[: len(exr) // 2])
bad = bytearray(exr)
for k in range(len(bad) // 2, len(bad), 3):
    bad[k] ^= 0x33
out("images", "corrupt.exr", bytes(bad))
jpg = read("g8.jpg")
out("images", "truncated.jpg", jpg[: len(jpg) // 2])
bad = bytearray(jpg)
for k in range(len(bad) // 3, len(bad) - 2, 4):
    bad[k] ^= 0x77
out("images", "corrupt.jpg", bytes(bad))
out("images", "text_named.dng", "this is a text file named like a RAW\n")
out("images", "tiff_named.nef", tif)  # a real TIFF that is not a Nikon RAW
print("corpus written below", HERE)

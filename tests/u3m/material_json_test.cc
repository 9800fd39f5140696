// Reader and writer of U3M JSON: round trips, foreign sections, deviations, malformed input.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "core/error.h"
#include "u3m/material_io.h"
#include "u3m/material_json.h"
#include "u3m_test_util.h"

namespace u3mscan {
namespace {

using test::Inline10;
using test::Inline11;
using test::JsonDifference;

bool HasIssue(const std::vector<Issue>& issues, const std::string& pointer, IssueSeverity severity) {
  return std::any_of(issues.begin(), issues.end(),
                     [&](const Issue& i) { return i.pointer == pointer && i.severity == severity; });
}

std::string Write(const Material& m, std::optional<SchemaVersion> version) {
  MaterialWriteOptions options;
  options.version = version;
  return WriteMaterialJson(m, options, "out.u3m").text;
}

TEST(MaterialJson, Reads11WithConversionsToTheNeutralModel) {
  const MaterialReadResult r = ReadMaterialJson(Inline11(), "inline.u3m");
  EXPECT_EQ(r.version, SchemaVersion::k1_1);
  const Material& m = r.material;
  EXPECT_EQ(m.id, "8b0a3c5e-1f2d-4e6a-9b7c-0d1e2f3a4b5c");  // braces and uppercase removed
  ASSERT_TRUE(m.front);
  EXPECT_FALSE(m.back);
  EXPECT_DOUBLE_EQ(m.front->anisotropy_rotation.constant, 90.0);  // 0.25 turn
  ASSERT_TRUE(m.front->anisotropy_rotation.texture);
  EXPECT_DOUBLE_EQ(m.front->anisotropy_rotation.texture->offset, 45.0);
  ASSERT_TRUE(m.front->basecolor.texture);
  EXPECT_DOUBLE_EQ(m.front->basecolor.texture->image.width_mm, 25.4);
  EXPECT_DOUBLE_EQ(m.front->basecolor.texture->image.dpi_y, 150.0);
  EXPECT_EQ(m.front->basecolor.texture->image.path, "textures/base color.png");
  EXPECT_DOUBLE_EQ(m.front->normal.texture->scale, 1.5);
  EXPECT_DOUBLE_EQ(m.front->normal.constant.y, -0.2);
  ASSERT_TRUE(m.front->preview);
  ASSERT_TRUE(m.physics);
  EXPECT_DOUBLE_EQ(*m.physics->weight_g_per_m2, 210.5);
  ASSERT_TRUE(m.physics->composition);
  EXPECT_EQ((*m.physics->composition)[1].name, "Seacell");
  EXPECT_TRUE(m.physics->fab_path.empty());
  // 2022-01-02T03:04:05.250+01:00 = 02:04:05.250 UTC
  EXPECT_EQ(FormatUtcTimestamp(m.modified_ms), "2022-01-02T02:04:05.250Z");
  // Deviations, each with its pointer.
  EXPECT_TRUE(HasIssue(r.issues, "/material/created", IssueSeverity::kError));  // no zone
  EXPECT_TRUE(HasIssue(r.issues, "/material/modified", IssueSeverity::kWarning));  // offset
  EXPECT_TRUE(HasIssue(r.issues, "/material/id", IssueSeverity::kWarning));
}

TEST(MaterialJson, RoundTrip11To11KeepsEverything) {
  const Material m1 = ReadMaterialJson(Inline11(), "a.u3m").material;
  const std::string t1 = Write(m1, SchemaVersion::k1_1);
  const MaterialReadResult r2 = ReadMaterialJson(t1, "b.u3m");
  EXPECT_TRUE(r2.issues.empty()) << r2.issues.front().pointer << ": " << r2.issues.front().message;
  EXPECT_TRUE(r2.material == m1);  // 1.1 holds the model's units as they are: exact
  EXPECT_EQ(Write(r2.material, SchemaVersion::k1_1), t1);
}

TEST(MaterialJson, RoundTrip10To10KeepsEverythingIncludingNull) {
  const MaterialReadResult r1 = ReadMaterialJson(Inline10("null"), "a.u3m");
  EXPECT_EQ(r1.version, SchemaVersion::k1_0);
  const Material& m1 = r1.material;
  EXPECT_FALSE(m1.front->transmission.used);  // 1.0 null: parameter not used
  EXPECT_DOUBLE_EQ(m1.front->basecolor.texture->image.width_mm, 50.8);  // 5.08 cm
  EXPECT_DOUBLE_EQ(m1.front->normal.texture->scale, 2.0);               // 1.0 factor
  EXPECT_DOUBLE_EQ(m1.front->anisotropy_rotation.constant, 90.0);       // degrees as they are
  const std::string t1 = Write(m1, std::nullopt);  // lowest version: 1.0
  EXPECT_NE(t1.find("\"schema\": \"1.0\""), std::string::npos);
  EXPECT_NE(t1.find("\"transmission\": null"), std::string::npos);
  const MaterialReadResult r2 = ReadMaterialJson(t1, "b.u3m");
  EXPECT_TRUE(r2.issues.empty()) << r2.issues.front().pointer << ": " << r2.issues.front().message;
  EXPECT_EQ(JsonDifference(ParseJson(Write(r2.material, SchemaVersion::k1_0), "x"), ParseJson(t1, "y")), "");
  EXPECT_EQ(ParseJson(t1, "x").Find("custom")->members().front().first, "Vizoo");
}

TEST(MaterialJson, RoundTrip10To11To10PreservesWhatBothHold) {
  const Material m1 = ReadMaterialJson(Inline10(), "a.u3m").material;
  const std::string t10 = Write(m1, SchemaVersion::k1_0);
  const std::string t11 = Write(m1, SchemaVersion::k1_1);
  // The 1.1 form: mm, {x, y}, turns.
  const JsonValue j11 = ParseJson(t11, "t11");
  const JsonValue& front = *j11.Find("material")->Find("front");
  const JsonValue& image = *front.Find("basecolor")->Find("texture")->Find("image");
  EXPECT_DOUBLE_EQ(image.Find("width")->number(), 50.8);
  EXPECT_DOUBLE_EQ(image.Find("dpi")->Find("y")->number(), 254.0);
  EXPECT_DOUBLE_EQ(front.Find("anisotropy_rotation")->Find("constant")->number(), 0.25);
  EXPECT_DOUBLE_EQ(front.Find("anisotropy_rotation")->Find("texture")->Find("factor")->number(), 1.0);
  EXPECT_DOUBLE_EQ(front.Find("anisotropy_rotation")->Find("texture")->Find("offset")->number(), 0.125);
  EXPECT_DOUBLE_EQ(front.Find("normal")->Find("texture")->Find("scale")->number(), 2.0);
  // And back: the same 1.0 document.
  const MaterialReadResult r = ReadMaterialJson(t11, "t11");
  EXPECT_TRUE(r.issues.empty()) << r.issues.front().pointer << ": " << r.issues.front().message;
  EXPECT_EQ(JsonDifference(ParseJson(Write(r.material, SchemaVersion::k1_0), "back"), ParseJson(t10, "t10")), "");
}

TEST(MaterialJson, NullParameterBecomesDefaultIn11WithANote) {
  const Material m = ReadMaterialJson(Inline10("null"), "a.u3m").material;
  MaterialWriteOptions options;
  options.version = SchemaVersion::k1_1;
  const MaterialWriteResult w = WriteMaterialJson(m, options, "out.u3m");
  EXPECT_TRUE(HasIssue(w.notes, "/material/front/transmission", IssueSeverity::kWarning));
  const JsonValue written = ParseJson(w.text, "x");
  const JsonValue& t = *written.Find("material")->Find("front")->Find("transmission");
  ASSERT_TRUE(t.is_object());
  EXPECT_EQ(t.Find("constant")->number(), 0.0);
  EXPECT_TRUE(t.Find("texture")->is_null());
}

TEST(MaterialJson, ForeignCustomSurvivesByteForValue) {
  const Material m = ReadMaterialJson(Inline11(), "a.u3m").material;
  for (SchemaVersion version : {SchemaVersion::k1_1}) {
    const std::string text = Write(m, version);
    for (const char* spelling : {"0.49803921580314639", "1.0", "1E5", "-0.0", "123456789012345678901234567890",
                                 "0.1000000000000000055511151231257827", "2.50", "3.14159265358979323846", "2.000"})
      EXPECT_NE(text.find(spelling), std::string::npos) << spelling;
    const JsonValue original = ParseJson(test::kForeignCustom, "custom");
    EXPECT_TRUE(*ParseJson(text, "x").Find("custom") == original);  // keys, order, spellings
    EXPECT_TRUE(*ParseJson(text, "x").Find("material")->Find("metadata") ==
                *ParseJson(Inline11(), "y").Find("material")->Find("metadata"));
  }
  // Through 1.0 (no metadata there): drop physics/metadata so 1.0 can hold it, custom unchanged.
  Material m10 = m;
  m10.physics.reset();
  m10.metadata = JsonValue();
  m10.front->preview.reset();
  m10.front->normal.constant = Vec3{};
  m10.front->basecolor.texture->image.dpi_y = m10.front->basecolor.texture->image.dpi_x;
  const std::string t10 = Write(m10, SchemaVersion::k1_0);
  EXPECT_TRUE(*ParseJson(t10, "x").Find("custom") == ParseJson(test::kForeignCustom, "custom"));
}

TEST(MaterialJson, WritesLowestVersionAndRefusesWhatAForcedVersionCannotHold) {
  Material m = ReadMaterialJson(Inline10(), "a.u3m").material;
  EXPECT_EQ(WriteMaterialJson(m, {}, "o.u3m").version, SchemaVersion::k1_0);
  m.side = Visualization{};
  EXPECT_EQ(WriteMaterialJson(m, {}, "o.u3m").version, SchemaVersion::k1_1);
  MaterialWriteOptions force10;
  force10.version = SchemaVersion::k1_0;
  try {
    WriteMaterialJson(m, force10, "o.u3m");
    FAIL() << "1.0 cannot hold a side";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/material/side"), std::string::npos) << e.what();
  }
  // 1.1 cannot hold an alpha above 1, 1.0 can.
  Material alpha = ReadMaterialJson(Inline10(), "a.u3m").material;
  alpha.front->alpha.constant = 1.5;
  MaterialWriteOptions force11;
  force11.version = SchemaVersion::k1_1;
  EXPECT_THROW(WriteMaterialJson(alpha, force11, "o.u3m"), InputError);
  EXPECT_EQ(WriteMaterialJson(alpha, {}, "o.u3m").version, SchemaVersion::k1_0);
}

TEST(MaterialJson, WriterFollowsTheConventions) {
  Material m = ReadMaterialJson(Inline11(), "a.u3m").material;
  m.id = "not-a-uuid";
  const MaterialWriteResult w = WriteMaterialJson(m, {}, "o.u3m");
  const JsonValue j = ParseJson(w.text, "o");
  const std::string id = j.Find("material")->Find("id")->text();
  EXPECT_TRUE(IsUuid4(id));
  EXPECT_EQ(id, [&] { std::string s = id; std::transform(s.begin(), s.end(), s.begin(), ::tolower); return s; }());
  EXPECT_TRUE(HasIssue(w.notes, "/material/id", IssueSeverity::kWarning));
  EXPECT_EQ(j.Find("material")->Find("created")->text(), "2021-10-19T15:41:23Z");
  // Paths the conventions forbid are refused, not written.
  for (const char* bad : {"textures\\a.png", "/abs.png", "../up.png", "C:/x.png", "a/./b.png", "dot.", "space ", "con.png"}) {
    Material p = m;
    p.front->displacement.texture->image.path = bad;
    EXPECT_THROW(WriteMaterialJson(p, {}, "o.u3m"), InputError) << bad;
  }
  m.name.clear();
  EXPECT_THROW(WriteMaterialJson(m, {}, "o.u3m"), InputError);
}

TEST(MaterialJson, AnisotropyRotationWrapsIntoOneTurnFor11) {
  Material m = ReadMaterialJson(Inline10(), "a.u3m").material;
  m.front->anisotropy_rotation.constant = -90.0;
  MaterialWriteOptions force11;
  force11.version = SchemaVersion::k1_1;
  const JsonValue j = ParseJson(WriteMaterialJson(m, force11, "o").text, "o");
  EXPECT_DOUBLE_EQ(j.Find("material")->Find("front")->Find("anisotropy_rotation")->Find("constant")->number(), 0.75);
}

// A 1.1 rotation within the reader's bound in turns leaves it in 1.0's degrees: the writer refuses
// it, naming the field, rather than write a file that does not read back (fuzz_u3m_json's crash).
TEST(MaterialJson, WriterRefusesANumberItsReaderWouldRefuse) {
  Material m = ReadMaterialJson(Inline10(), "a.u3m").material;
  m.front->anisotropy_rotation.constant = 422175765.0 * 360.0;  // as read from 422175765 turns
  MaterialWriteOptions force10;
  force10.version = SchemaVersion::k1_0;
  try {
    WriteMaterialJson(m, force10, "o.u3m");
    ADD_FAILURE() << "a constant of 1.5e11 was written";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/material/front/anisotropy_rotation/constant"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("1e9"), std::string::npos) << e.what();
  }
  // 1.1 wraps the rotation into one turn: that material is written.
  MaterialWriteOptions force11;
  force11.version = SchemaVersion::k1_1;
  EXPECT_NO_THROW(WriteMaterialJson(m, force11, "o.u3m"));
}

struct Malformed {
  std::string name;
  std::string text;
  std::string pointer;  // expected field of the InputError ("" = anywhere)
};

std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const auto pos = text.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  return pos == std::string::npos ? text : text.replace(pos, from.size(), to);
}

TEST(MaterialJson, MalformedInputGivesAClearErrorNeverACrash) {
  const std::string good = Inline11();
  const std::vector<Malformed> cases = {
      {"truncated", good.substr(0, good.size() / 2), ""},
      {"empty", "", ""},
      {"nan", Replace(good, "\"ior\": {\"constant\": 1.5", "\"ior\": {\"constant\": NaN"), "/material/front/ior/constant"},
      {"infinity literal", Replace(good, "\"constant\": 0.7", "\"constant\": Infinity"), "/material/front/roughness/constant"},
      {"overflow", Replace(good, "\"constant\": 0.7", "\"constant\": 1e999"), "/material/front/roughness/constant"},
      {"huge", Replace(good, "\"constant\": 0.7", "\"constant\": 1e300"), "/material/front/roughness/constant"},
      {"huge in physics", Replace(good, "\"weight\": 210.5", "\"weight\": -1e200"), "/material/physics/weight"},
      {"duplicate key", Replace(good, "\"name\": \"Inline 1.1\",", "\"name\": \"a\", \"name\": \"b\","), "/material/name"},
      {"duplicate in custom", Replace(good, "\"k\": 3.14", "\"k\": 1, \"k\": 3.14"), "/custom/Another/k"},
      {"wrong type", Replace(good, "\"constant\": 0.7", "\"constant\": \"0.7\""), "/material/front/roughness/constant"},
      {"wrong type side", Replace(good, "\"back\": null", "\"back\": []"), "/material/back"},
      {"wrong type custom", Replace(good, "\"custom\": {", "\"custom\": [{"), ""},
      {"schema version", Replace(good, "\"schema\": \"1.1\"", "\"schema\": \"2.0\""), "/schema"},
      {"traversal", Replace(good, "textures/disp.png", "../../etc/passwd"), "/material/front/displacement/texture/image/path"},
      {"absolute", Replace(good, "textures/disp.png", "/etc/passwd"), "/material/front/displacement/texture/image/path"},
      {"drive", Replace(good, "textures/disp.png", "C:\\\\Windows\\\\x.png"), "/material/front/displacement/texture/image/path"},
      {"backslash traversal", Replace(good, "textures/disp.png", "textures\\\\..\\\\..\\\\x.png"), "/material/front/displacement/texture/image/path"},
      {"preview traversal", Replace(good, "\"path\": \"preview.png\"", "\"path\": \"../preview.png\""), "/material/front/preview/path"},
      {"bad timestamp", Replace(good, "2021-10-19T15:41:23", "yesterday"), "/material/created"},
      {"bad date", Replace(good, "2021-10-19T15:41:23", "2021-02-30T15:41:23"), "/material/created"},
      {"deep nesting", Replace(good, "\"a_last\": {}", "\"a_last\": " + std::string(5000, '[') + std::string(5000, ']')), ""},
      {"not an object", "[1, 2, 3]", ""},
      {"comment", "// hello\n" + good, ""},
      {"binary garbage", std::string("\x89PNG\r\n\x1a\n\0\0\0", 11), ""},
  };
  for (const Malformed& c : cases) {
    try {
      ReadMaterialJson(c.text, "bad.u3m");
      ADD_FAILURE() << c.name << ": no error";
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "bad.u3m") << c.name;
      EXPECT_NE(e.expected().find("expected"), std::string::npos) << c.name << ": " << e.what();
      if (!c.pointer.empty()) {
        EXPECT_EQ(e.field(), c.pointer) << c.name << ": " << e.what();
      }
    }
  }
}

// Random damage (fixed seed): every mutant either reads (and then writes valid text or refuses with
// InputError) or is refused with InputError; nothing else escapes, nothing crashes.
TEST(MaterialJson, RandomlyDamagedDocumentsNeverEscapeAsOtherErrors) {
  constexpr int kMutants = 3000;
  std::mt19937 rng(20261122);
  const std::string sources[] = {Inline11(), Inline10(), Inline10("null")};
  const std::string alphabet = "{}[]\",:0123456789.eE+-truefalsnul \\/xyz";
  int read = 0, refused = 0;
  for (int i = 0; i < kMutants; ++i) {
    std::string text = sources[i % 3];
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits && !text.empty(); ++e) {
      const std::size_t pos = rng() % text.size();
      switch (rng() % 4) {
        case 0: text[pos] = alphabet[rng() % alphabet.size()]; break;
        case 1: text.erase(pos, 1 + rng() % 8); break;
        case 2: text.insert(pos, 1, alphabet[rng() % alphabet.size()]); break;
        case 3: text.resize(pos); break;
      }
    }
    try {
      const MaterialReadResult r = ReadMaterialJson(text, "mutant.u3m");
      ++read;
      try {
        const MaterialWriteResult w = WriteMaterialJson(r.material, {}, "out.u3m");
        const MaterialReadResult again = ReadMaterialJson(w.text, "out.u3m");  // what we write, we read
        for (const Issue& issue : again.issues)
          EXPECT_NE(issue.severity, IssueSeverity::kError) << "mutant " << i << ": " << issue.pointer << ": " << issue.message;
      } catch (const InputError&) {
      }
    } catch (const InputError&) {
      ++refused;
    }
  }
  EXPECT_EQ(read + refused, kMutants);
  EXPECT_GT(read, 0);
  EXPECT_GT(refused, 0);
}

TEST(MaterialJson, ToleratedDeviationsAreReportedWithPointers) {
  std::string text = Inline11();
  text = Replace(text, "\"ior\": {\"constant\": 1.5", "\"ior\": {\"constant\": 0");
  text = Replace(text, "textures/disp.png", "textures\\\\disp.png");
  text = Replace(text, "\"back\": null", "\"back\": null, \"vendor_key\": 1");
  text = Replace(text, "\"metalness\": {\"constant\": 0.0, \"texture\": null}", "\"metalness\": null");
  text = Replace(text, "\"dpi\": {\"x\": 72, \"y\": 72}", "\"dpi\": 72");
  text = Replace(text, "\"type\": \"Cotton\"", "\"type\": \"Bamboo\"");
  text = Replace(text, "\"r\": 0.25, \"g\": 0.5", "\"r\": 1.25, \"g\": 0.5");
  const MaterialReadResult r = ReadMaterialJson(text, "dev.u3m");
  EXPECT_TRUE(HasIssue(r.issues, "/material/front/ior/constant", IssueSeverity::kWarning));
  EXPECT_TRUE(HasIssue(r.issues, "/material/physics/composition/parts/0/type", IssueSeverity::kError));
  EXPECT_EQ((*r.material.physics->composition)[0].type, "other");
  EXPECT_EQ((*r.material.physics->composition)[0].name, "Bamboo");
  EXPECT_TRUE(HasIssue(r.issues, "/material/front/basecolor/constant/r", IssueSeverity::kError));
  EXPECT_EQ(r.material.front->basecolor.constant.r, 1.0);
  EXPECT_TRUE(HasIssue(r.issues, "/material/front/displacement/texture/image/path", IssueSeverity::kError));
  EXPECT_EQ(r.material.front->displacement.texture->image.path, "textures/disp.png");
  EXPECT_TRUE(HasIssue(r.issues, "/material/vendor_key", IssueSeverity::kError));
  EXPECT_TRUE(HasIssue(r.issues, "/material/front/metalness", IssueSeverity::kError));
  EXPECT_TRUE(HasIssue(r.issues, "/material/front/preview/dpi", IssueSeverity::kError));
  EXPECT_DOUBLE_EQ(r.material.front->preview->dpi_y, 72.0);
  // Whatever was tolerated, the writer's output is schema-clean; the value ior 0 is kept (with its warning).
  const MaterialReadResult again = ReadMaterialJson(WriteMaterialJson(r.material, {}, "o").text, "o");
  ASSERT_EQ(again.issues.size(), 1u) << again.issues.front().pointer << ": " << again.issues.front().message;
  EXPECT_TRUE(HasIssue(again.issues, "/material/front/ior/constant", IssueSeverity::kWarning));
}

TEST(MaterialJson, TimestampsParseAndFormat) {
  const auto t = ParseTimestamp("2018-07-16T12:38:00+02:00");
  ASSERT_TRUE(t);
  EXPECT_TRUE(t->has_offset);
  EXPECT_EQ(FormatUtcTimestamp(t->utc_ms), "2018-07-16T10:38:00Z");
  const auto z = ParseTimestamp("1999-12-31T23:59:59.5Z");
  ASSERT_TRUE(z);
  EXPECT_FALSE(z->has_offset);
  EXPECT_EQ(FormatUtcTimestamp(z->utc_ms), "1999-12-31T23:59:59.500Z");
  const auto naive = ParseTimestamp("2021-10-19T15:41:23");
  ASSERT_TRUE(naive);
  EXPECT_FALSE(naive->has_zone);
  EXPECT_EQ(FormatUtcTimestamp(naive->utc_ms), "2021-10-19T15:41:23Z");
  EXPECT_EQ(FormatUtcTimestamp(0), "1970-01-01T00:00:00Z");
  for (const char* bad : {"2021-13-01T00:00:00Z", "2021-10-19", "2021-10-19T25:00:00Z", "2021-10-19T15:41:23+2", "x"})
    EXPECT_FALSE(ParseTimestamp(bad)) << bad;
}

TEST(MaterialJson, NewUuidsAreLowercaseVersion4) {
  for (int i = 0; i < 100; ++i) {
    const std::string id = NewUuid4();
    EXPECT_TRUE(IsUuid4(id)) << id;
    EXPECT_EQ(id.find_first_of("ABCDEF{}"), std::string::npos) << id;
  }
  EXPECT_FALSE(IsUuid4("45d231aa-96a0-1d94-9aae-4a99fae0e32a"));  // version 1
  EXPECT_FALSE(IsUuid4("45d231aa-96a0-4d94-7aae-4a99fae0e32a"));  // variant 0
}

// The vendor samples read with exactly the deviations they are known for.
TEST(MaterialJsonSamples, BrowzwearAndVizooSamplesReadWithExpectedWarnings) {
  if (!test::SharedReferencePresent()) GTEST_SKIP() << "no " << test::SharedReference() << ": sample tests skipped";
  const LoadedMaterial fleece = LoadMaterial(test::SharedReference() / "samples/browzwear-1.1-polartec-fleece.u3ma");
  EXPECT_EQ(fleece.version, SchemaVersion::k1_1);
  EXPECT_TRUE(HasIssue(fleece.issues, "/material/created", IssueSeverity::kError));
  EXPECT_TRUE(HasIssue(fleece.issues, "/material/modified", IssueSeverity::kError));
  EXPECT_TRUE(HasIssue(fleece.issues, "/material/id", IssueSeverity::kWarning));
  EXPECT_TRUE(HasIssue(fleece.issues, "/material/front/metalness/constant", IssueSeverity::kWarning));
  EXPECT_EQ(fleece.material.custom.members().size(), 2u);

  const LoadedMaterial fb = LoadMaterial(test::SharedReference() / "samples/browzwear-1.1-front-back/Fleece_60_Cotton_40_Poly_304gsm.u3m");
  EXPECT_TRUE(HasIssue(fb.issues, "/material/front/ior/constant", IssueSeverity::kWarning));
  EXPECT_TRUE(HasIssue(fb.issues, "/material/back/ior/constant", IssueSeverity::kWarning));
  EXPECT_TRUE(fb.material.back.has_value());
  EXPECT_EQ(fb.material.physics->fab_path, "physics.json");

  const LoadedMaterial example = LoadMaterial(test::SharedReference() / "1.0/Example_1.0.u3m");
  EXPECT_EQ(example.version, SchemaVersion::k1_0);
  EXPECT_TRUE(HasIssue(example.issues, "/material/created", IssueSeverity::kWarning));  // +02:00
  EXPECT_EQ(FormatUtcTimestamp(example.material.created_ms), "2018-07-16T10:38:00Z");
  for (const Issue& issue : example.issues) EXPECT_NE(issue.severity, IssueSeverity::kError) << issue.pointer;
}

TEST(MaterialJsonSamples, SampleCustomSectionsSurviveARewriteUnchanged) {
  if (!test::SharedReferencePresent()) GTEST_SKIP() << "no " << test::SharedReference() << ": sample tests skipped";
  for (const char* sample : {"samples/browzwear-1.1-front-back/Fleece_60_Cotton_40_Poly_304gsm.u3m", "1.0/Example_1.0.u3m"}) {
    const std::string text = test::ReadFile(test::SharedReference() / sample);
    const Material m = ReadMaterialJson(text, sample).material;
    const std::string written = WriteMaterialJson(m, {}, "out.u3m").text;
    EXPECT_TRUE(*ParseJson(written, "out").Find("custom") == *ParseJson(text, sample).Find("custom")) << sample;
  }
}

}  // namespace
}  // namespace u3mscan

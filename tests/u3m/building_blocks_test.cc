// The small pieces under the reader and writer: JSON tree, path rules, texture means.
#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "u3m/json_value.h"
#include "u3m/relative_path.h"
#include "u3m/texture_stats.h"

namespace u3mscan {
namespace {

constexpr double kMeanTol = 1e-12;

TEST(JsonValue, KeepsOrderSpellingAndEscapesOnlyWhatJsonNeeds) {
  const std::string text = R"({"b": 1.50, "a": [1E+2, -0.0, 18446744073709551616], "s": "tab\t\"q\" \u00e9 \u0001"})";
  const JsonValue v = ParseJson(text, "t");
  ASSERT_TRUE(v.is_object());
  EXPECT_EQ(v.members()[0].first, "b");
  EXPECT_EQ(v.Find("b")->text(), "1.50");
  EXPECT_EQ(v.Find("a")->items()[0].text(), "1E+2");
  EXPECT_EQ(v.Find("a")->items()[1].text(), "-0.0");
  EXPECT_EQ(v.Find("a")->items()[2].text(), "18446744073709551616");  // beyond uint64: kept as written
  const std::string written = WriteJson(v, 0);
  EXPECT_EQ(written, "{\"b\":1.50,\"a\":[1E+2,-0.0,18446744073709551616],\"s\":\"tab\\t\\\"q\\\" \xC3\xA9 \\u0001\"}");
  EXPECT_TRUE(ParseJson(written, "w") == v);
  EXPECT_EQ(JsonValue::Number(300.0).text(), "300");
  EXPECT_EQ(JsonValue::Number(0.1).text(), "0.1");
  EXPECT_EQ(JsonValue::Number(-0.0).text(), "0");
}

TEST(JsonValue, ErrorsNameThePointer) {
  const auto field_of = [](const std::string& text) {
    try {
      ParseJson(text, "t.json");
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "t.json");
      return e.field();
    }
    return std::string("no error");
  };
  EXPECT_EQ(field_of(R"({"a": {"b": [1, 2, nan]}})"), "/a/b/2");
  EXPECT_EQ(field_of(R"({"a": 1, "a": 2})"), "/a");
  EXPECT_EQ(field_of(R"({"x/y~z": {"k": 1, "k": 2}})"), "/x~1y~0z/k");
  EXPECT_EQ(field_of(R"({"a": 1,)"), "");
  std::string deepest;  // the 129th '[' fails inside 128 open arrays, each at index 0
  for (int i = 0; i < kMaxJsonDepth; ++i) deepest += "/0";
  EXPECT_EQ(field_of(std::string(kMaxJsonDepth + 1, '[')), deepest);
  EXPECT_EQ(field_of("[1] [2]"), "");
}

TEST(RelativePath, RefusesEscapesRepairsSlipsAndFlagsSchemaProblems) {
  for (const char* unsafe : {"", "/etc/x", "\\\\server\\x", "C:/x.png", "c:x.png", "../x", "a/../../x", "a\\..\\x",
                             "a/b:c.png", "a\nb.png"})
    EXPECT_TRUE(CheckRelativePath(unsafe).unsafe) << unsafe;
  const RelativePathCheck repaired = CheckRelativePath("textures\\./a.png");
  EXPECT_FALSE(repaired.unsafe);
  EXPECT_EQ(repaired.normalized, "textures/a.png");
  EXPECT_EQ(repaired.repairs.size(), 2u);
  EXPECT_TRUE(repaired.problems.empty());
  for (const char* flagged : {"a.png.", "a.png ", "con.png", "lpt1", "f%/a.png", "a|b.png", "~/a.png"})
    EXPECT_FALSE(CheckRelativePath(flagged).problems.empty()) << flagged;
  for (const char* fine : {"a.png", "textures/fleece 304_f_col.jpg", "textures/polartec fleece, 100% polyester.jpg",
                           "t/\xC3\xA9t\xC3\xA9.png", "concrete.png", "com10.png"})
    EXPECT_TRUE(IsWritableRelativePath(fine)) << fine;
}

// The rules on which the U3M reader and the .u3ma reader once differed, now one checker: the
// stricter rule holds for both spellings, and only the spelling slips are read differently.
TEST(RelativePath, UtfEightLengthAndSchemaRulesHoldForU3mPathsAndArchiveNames) {
  const std::string at_limit = std::string(kMaxRelativePathBytes - 4, 'a') + ".png";
  const std::string over_limit = "a" + at_limit;
  for (PathSpelling spelling : {PathSpelling::kRepair, PathSpelling::kExact}) {
    SCOPED_TRACE(spelling == PathSpelling::kRepair ? "repair" : "exact");
    // Not UTF-8 (the archive's rule): a truncated sequence, an overlong '/', a surrogate.
    for (const char* bad : {"t/\xC3.png", "t\xC0\xAFx.png", "t/\xED\xA0\x80.png"}) {
      const RelativePathCheck check = CheckRelativePath(bad, spelling);
      EXPECT_TRUE(check.unsafe) << bad;
      EXPECT_NE(check.unsafe_reason.find("UTF-8"), std::string::npos) << check.unsafe_reason;
    }
    // At most kMaxRelativePathBytes (the U3M reader's rule).
    EXPECT_FALSE(CheckRelativePath(at_limit, spelling).unsafe);
    EXPECT_TRUE(CheckRelativePath(over_limit, spelling).unsafe);
    // Names that break only the 1.1 pattern are flagged, not refused (the U3M reader's rule).
    for (const char* flagged : {"textures/con.png", "textures/a.png.", "f%/a.png", "a|b.png", "~/a.png"}) {
      const RelativePathCheck check = CheckRelativePath(flagged, spelling);
      EXPECT_FALSE(check.unsafe) << flagged;
      EXPECT_EQ(check.problems.size(), 1u) << flagged;
    }
  }
  EXPECT_NE(RelativePathProblem("textures/COM1.png").find("reserved"), std::string::npos);
  EXPECT_NE(RelativePathProblem("f%/a.png").find("pattern"), std::string::npos);
}

TEST(RelativePath, SpellingSlipsAreRepairedInAU3mAndRefusedAsArchiveNames) {
  for (const char* slip : {"a\\b.png", "./a.png", "a//b.png", "a/./b.png", "a/b.png/"}) {
    const RelativePathCheck repaired = CheckRelativePath(slip, PathSpelling::kRepair);
    EXPECT_FALSE(repaired.unsafe) << slip;
    EXPECT_FALSE(repaired.repairs.empty()) << slip;
    EXPECT_TRUE(CheckRelativePath(slip, PathSpelling::kExact).unsafe) << slip;
    EXPECT_FALSE(IsWritableRelativePath(slip)) << slip;
  }
  // Escapes are unsafe in both, also when only a backslash makes the '..' a segment.
  for (const char* escape : {"..\\x.png", "a\\..\\..\\x.png", "\\x.png"}) {
    EXPECT_TRUE(CheckRelativePath(escape, PathSpelling::kRepair).unsafe) << escape;
    EXPECT_TRUE(CheckRelativePath(escape, PathSpelling::kExact).unsafe) << escape;
  }
}

TEST(RelativePath, SanitizedNamesAreAlwaysWritable) {
  for (const char* name : {"a.png.", "a.png ", "CON.png", "x/../y.png", "a\\b.png", "f%/a$b.png", "<>:\"|", "~", ".",
                           "/abs/p.png", "C:/w.png", "t/\xC3\xA9.png", "caf\xE9.png"}) {
    const std::string sanitized = SanitizeRelativePath(name);
    std::string why;
    EXPECT_TRUE(IsWritableRelativePath(sanitized, &why)) << name << " -> " << sanitized << ": " << why;
  }
  EXPECT_EQ(SanitizeRelativePath("textures/CON.png"), "textures/_CON.png");
  EXPECT_EQ(SanitizeRelativePath("a\\b.png"), "a/b.png");
  EXPECT_EQ(SanitizeRelativePath("caf\xE9.png"), "caf_.png");  // Latin-1, not UTF-8
  EXPECT_EQ(SanitizeRelativePath("t/\xC3\xA9.png"), "t/\xC3\xA9.png");
}

TEST(TextureStats, BlendModesFollowTheSpecification) {
  EXPECT_DOUBLE_EQ(Blend(BlendMode::kAdd, 0.25, 0.5), 0.75);
  EXPECT_DOUBLE_EQ(Blend(BlendMode::kSubtract, 0.75, 0.5), 0.25);
  EXPECT_DOUBLE_EQ(Blend(BlendMode::kMultiply, 0.5, 0.5), 0.25);
  EXPECT_DOUBLE_EQ(Blend(BlendMode::kDivide, 0.25, 0.5), 0.5);
  EXPECT_DOUBLE_EQ(Blend(BlendMode::kMax, 0.25, 0.5), 0.5);
  EXPECT_DOUBLE_EQ(Blend(BlendMode::kMin, 0.25, 0.5), 0.25);
  for (double i : {0.1, 0.4, 0.6, 0.9}) EXPECT_NEAR(Blend(BlendMode::kOverlay, i, 0.5), i, kMeanTol);  // neutral grey
  EXPECT_DOUBLE_EQ(Blend(BlendMode::kOverlay, 0.25, 1.0), 0.5);
}

TEST(TextureStats, MeansAreOfTheFinalValue) {
  Image ramp(4, 2, 3, 0.0f);
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 4; ++c) {
      ramp.at(0, r, c) = 0.25f * c;  // R: 0, .25, .5, .75 -> mean 0.375
      ramp.at(1, r, c) = 0.5f;
      ramp.at(2, r, c) = 1.0f;
    }
  // Scalar: offset + average(channels) * factor; average of channels = (0.375 + 0.5 + 1) / 3.
  EXPECT_NEAR(ScalarTextureMean(ramp, 2.0, -0.5), -0.5 + 2.0 * (0.375 + 0.5 + 1.0) / 3.0, kMeanTol);
  const Rgb3 colour = ColorTextureMean(ramp, BlendMode::kAdd, Rgb3{0.5, 0.5, 0.5});
  EXPECT_NEAR(colour.r, (0.5 + 0.75 + 1.0 + 1.0) / 4.0, kMeanTol);  // clamped per pixel, then averaged
  EXPECT_NEAR(colour.g, 1.0, kMeanTol);
  EXPECT_NEAR(colour.b, 1.0, kMeanTol);
  // Normals: encoded (n+1)/2; a map tilted toward +x by 45 degrees, scale 0 flattens it.
  Image tilted(2, 2, 3, 0.0f);
  const float s = static_cast<float>(std::sqrt(0.5));
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 2; ++c) {
      tilted.at(0, r, c) = (s + 1.0f) / 2.0f;
      tilted.at(1, r, c) = 0.5f;
      tilted.at(2, r, c) = (s + 1.0f) / 2.0f;
    }
  EXPECT_NEAR(NormalTextureMean(tilted, 1.0).x, std::sqrt(0.5), 1e-6);
  EXPECT_NEAR(NormalTextureMean(tilted, 0.0).z, 1.0, 1e-6);
  EXPECT_TRUE(ConstantAgrees(0.5, 0.51));
  EXPECT_FALSE(ConstantAgrees(0.5, 0.56));
}

}  // namespace
}  // namespace u3mscan

#include "core/colour.h"

#include <gtest/gtest.h>

namespace u3mscan {
namespace {

constexpr double kRoundTripTolerance = 1e-12;
// Sharma, Wu, Dalal (2005) publish their test data to 4 decimals.
constexpr double kCiede2000Tolerance = 1e-4;

TEST(Colour, SrgbRoundTripIsIdentity) {
  for (int i = 0; i <= 100; ++i) {
    const double v = i / 100.0;
    EXPECT_NEAR(LinearToSrgb(SrgbToLinear(v)), v, kRoundTripTolerance) << v;
  }
}

TEST(Colour, SrgbKnownValues) {
  EXPECT_NEAR(SrgbToLinear(0.5), 0.214041140, 1e-9);
  EXPECT_NEAR(SrgbToLinear(0.04045), 0.04045 / 12.92, 1e-12);  // knee of the piecewise curve
  EXPECT_DOUBLE_EQ(LinearToSrgb(2.0), 1.0);                      // clamped
  EXPECT_DOUBLE_EQ(LinearToSrgb(-1.0), 0.0);
}

TEST(Colour, WhiteIsLab100) {
  const Lab white = LinearSrgbToLab({1.0, 1.0, 1.0});
  EXPECT_NEAR(white[0], 100.0, 1e-3);
  EXPECT_NEAR(white[1], 0.0, 1e-2);
  EXPECT_NEAR(white[2], 0.0, 1e-2);
}

struct Ciede2000Case {
  Lab a, b;
  double expected;
};

TEST(Colour, Ciede2000MatchesSharmaTestData) {
  const Ciede2000Case cases[] = {
      {{50.0, 2.6772, -79.7751}, {50.0, 0.0, -82.7485}, 2.0425},
      {{50.0, 0.0, 0.0}, {50.0, -1.0, 2.0}, 2.3669},
      {{50.0, 2.5, 0.0}, {73.0, 25.0, -18.0}, 27.1492},
      {{60.2574, -34.0099, 36.2677}, {60.4626, -34.1751, 39.4387}, 1.2644},
      {{50.0, 2.5, 0.0}, {50.0, 0.0, -2.5}, 4.3065},
  };
  for (const auto& c : cases) {
    EXPECT_NEAR(Ciede2000(c.a, c.b), c.expected, kCiede2000Tolerance);
    EXPECT_NEAR(Ciede2000(c.b, c.a), c.expected, kCiede2000Tolerance) << "symmetry";
  }
  EXPECT_DOUBLE_EQ(Ciede2000({40, 10, -5}, {40, 10, -5}), 0.0);
}

}  // namespace
}  // namespace u3mscan

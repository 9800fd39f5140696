#include "core/markup_escape.h"

#include <gtest/gtest.h>

namespace u3mscan {
namespace {

TEST(EscapeMarkup, ReplacesEveryMarkupCharacter) {
  EXPECT_EQ(EscapeMarkup("a<b>&\"c'"), "a&lt;b&gt;&amp;&quot;c&#39;");
}

TEST(EscapeMarkup, LeavesOtherTextAndUtf8Alone) {
  EXPECT_EQ(EscapeMarkup("twill 0.5 mm \xC2\xB5m"), "twill 0.5 mm \xC2\xB5m");
  EXPECT_EQ(EscapeMarkup(""), "");
}

TEST(EscapeMarkup, EscapesAnAmpersandOnlyOnce) {
  // An already escaped reference is text like any other: its & is escaped again, never skipped.
  EXPECT_EQ(EscapeMarkup("&amp;"), "&amp;amp;");
}

}  // namespace
}  // namespace u3mscan

#pragma once
// Escaping text for XML and HTML (the SVG plots of the bench, the self-contained report.html).

#include <string>

namespace u3mscan {

// Replaces &, <, >, " and ' by character references, so that the text is safe both as element
// content and inside a quoted attribute. &#39; (not &apos;) for ': valid in XML and every HTML.
std::string EscapeMarkup(const std::string& text);

}  // namespace u3mscan

#pragma once
// The --size WIDTHxHEIGHT option of the commands that render images (synth, synth-ball).

#include <string>

namespace u3mscan::cli {

// "7360x4912" -> width, height. Throws InputError naming --size, with `example` ("64x64") in the
// message, for anything else. The ranges are the caller's to check.
void ParseSizeOption(const std::string& text, const std::string& example, int* width, int* height);

}  // namespace u3mscan::cli

#pragma once
// Writing a text file whole or not at all: reports, tables and the text files of a synthetic data
// set.

#include <filesystem>
#include <string>

namespace u3mscan {

// Writes `text` to `path` through a temporary file beside it (`path` + ".partial") and a rename,
// so that a reader never sees half a file and a failed write leaves the old file (or none).
// Throws InputError naming `path`, with `what` as the expectation ("a writable location for the
// report"), when the file cannot be written or renamed into place.
void WriteTextFileAtomically(const std::filesystem::path& path, const std::string& text,
                             const std::string& what = "a writable location");

}  // namespace u3mscan

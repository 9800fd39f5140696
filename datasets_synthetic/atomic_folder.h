#pragma once
// A folder written whole or not at all: what the synthetic scanner writes (a capture with its
// truth, a DiLiGenT-format object) appears under its name only once every file is in it.

#include <filesystem>
#include <functional>

namespace u3mscan::synthetic {

// Calls write(staging) with an empty staging folder beside out_dir (".NAME.partial-PID"), then
// renames it to out_dir. out_dir must not exist or be an empty folder (the one a caller may have
// made). Throws InputError naming out_dir when it cannot be used or its parent cannot be made;
// whatever write throws is rethrown after the staging folder is removed, so a failure leaves no
// out_dir behind.
void WriteFolderAtomically(const std::filesystem::path& out_dir, const std::function<void(const std::filesystem::path& staging)>& write);

}  // namespace u3mscan::synthetic

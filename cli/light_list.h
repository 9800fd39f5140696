#pragma once
// `--hold-out-lights L03,L09`: one comma-separated string (a CLI11 vector option would also swallow
// the capture paths that follow it on a command line), split into light ids.

#include <sstream>
#include <string>
#include <vector>

namespace u3mscan::cli {

// The ids in `list`, in order; an empty id between commas or after a last comma is kept (as "") so
// that the check on the ids names it.
inline std::vector<std::string> SplitLightIds(const std::string& list) {
  std::vector<std::string> ids;
  if (list.empty()) return ids;
  std::stringstream in(list);
  for (std::string id; std::getline(in, id, ',');) ids.push_back(id);
  if (list.back() == ',') ids.push_back("");  // "L03," names an empty id
  return ids;
}

}  // namespace u3mscan::cli

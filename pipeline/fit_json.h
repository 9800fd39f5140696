#pragma once
// fit.json (`u3mscan fit`): the fit's report as JSON. The map decisions (measured / constant / left
// out and why, with U3M key names), per-cluster parameters with uncertainties, convergence, times
// per stage and the main options; format in docs/fitting.md, "Output (`FitResult`) and `fit.json`".
// Keys in that order (ordered_json); numbers that are not finite (the std of a parameter left
// out) are null.

#include <nlohmann/json.hpp>

#include "fitting/principled_fit.h"

namespace u3mscan::pipeline {

nlohmann::ordered_json FitResultToJson(const fitting::FitResult& result);

}  // namespace u3mscan::pipeline

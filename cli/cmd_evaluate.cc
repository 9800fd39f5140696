// `u3mscan evaluate OUTPUT TRUTH`: the synthetic round-trip check. Compares a processed output
// (`u3mscan process --debug-maps`) with the truth/ folder of a synthetic capture and prints every
// error figure (bench/evaluate.h, docs/bench.md), then which of the issues' targets they meet
// (bench/issue_targets.h).
#include <iostream>

#include "bench/evaluate.h"
#include "bench/issue_targets.h"
#include "cli/command.h"
#include "core/error.h"
#include "core/text_file.h"

namespace u3mscan::cli {
namespace {

struct EvaluateArgs {
  std::string output, truth, json_file;
  bench::EvaluateOptions options;
};

U3MSCAN_REGISTER_COMMAND(kEvaluateCommand, "evaluate",
                         "Errors of a processed synthetic capture against its truth, and which of the issues' targets they meet", 60,
                         [](CLI::App& sub) {
  auto args = std::make_shared<EvaluateArgs>();
  sub.add_option("OUTPUT", args->output, "Output folder of `u3mscan process --debug-maps` (report.json, maps/)")->required();
  sub.add_option("TRUTH", args->truth, "The synthetic capture's truth/ folder (truth.json + maps)")->required();
  sub.add_option("--json", args->json_file, "Also write every figure to this JSON file");
  sub.add_option("--side", args->options.side, "front | back")->capture_default_str();
  sub.add_option("--held-out-lights", args->options.max_held_out_lights, "Most held-out lights for the re-render error")
      ->capture_default_str();
  return std::function<int()>([args] {
    try {
      const bench::Evaluation evaluation = bench::Evaluate(args->output, args->truth, args->options);
      const auto targets = bench::CheckAgainstTheTargets(evaluation);
      std::cout << bench::EvaluationToText(evaluation) << bench::TargetsToText(targets, evaluation.scene);
      if (!args->json_file.empty()) {
        nlohmann::json figures = bench::EvaluationToJson(evaluation);
        figures["targets"] = bench::TargetsToJson(targets);
        WriteTextFileAtomically(args->json_file, figures.dump(2) + "\n", "a writable file");
      }
      return kExitOk;
    } catch (const InputError& e) {
      std::cerr << "error: " << e.what() << "\n";
      return kExitUsage;
    }
  });
});

}  // namespace
}  // namespace u3mscan::cli

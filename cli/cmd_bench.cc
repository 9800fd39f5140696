// `u3mscan bench [--quick] [-o DIR]`: error against run time over a matrix of synthetic captures
// (bench/bench.h, docs/bench.md); `--diligent ROOT`: photometric stereo on DiLiGenT-format objects
// (bench/diligent.h). Each case runs `u3mscan process` in a child process of this
// same executable.
#include <unistd.h>

#include <filesystem>
#include <iostream>

#include "bench/bench.h"
#include "bench/diligent.h"
#include "cli/command.h"
#include "core/error.h"

namespace u3mscan::cli {
namespace {

std::filesystem::path SelfExecutable(const char* fallback) {
  std::error_code ec;
  const auto self = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::path(fallback) : self;
}

U3MSCAN_REGISTER_COMMAND(kBenchCommand, "bench", "Error against run time on synthetic captures (bench.csv, bench.md, SVG plots)", 70,
                         [](CLI::App& sub) {
  auto options = std::make_shared<bench::BenchOptions>();
  auto diligent_root = std::make_shared<std::string>();
  CLI::Option* quick = sub.add_flag("--quick", options->quick, "Tiny sizes and few scenes (about a minute on 2 cores; for CI)");
  sub.add_option("-o,--out", options->out_dir, "Output folder for bench.csv, bench.md and the plots")->capture_default_str();
  CLI::Option* threads = sub.add_option("--threads", options->threads, "Threads of each `u3mscan process` run (0: all cores)")->check(CLI::Range(0, 1024));
  CLI::Option* seed = sub.add_option("--seed", options->seed, "Seed of the synthetic captures")->capture_default_str();
  CLI::Option* keep_work = sub.add_flag("--keep-work", options->keep_work, "Keep the captures and run outputs under OUT/work");
  CLI::Option* only = sub.add_option("--only", options->only, "Run only the cases whose name contains one of these (e.g. knit_distant_128_balanced)")
      ->delimiter(',');
  sub.add_option("--diligent", *diligent_root,
                 "Instead of the synthetic matrix: photometric stereo on the DiLiGenT-format objects under ROOT (an object "
                 "folder, or DiLiGenT's pmsData), every solver, errors against their true normals (diligent.csv, diligent.md; "
                 "`u3mscan synth-ball` writes such an object)")
      ->type_name("ROOT")
      ->excludes(quick)
      ->excludes(threads)
      ->excludes(seed)
      ->excludes(keep_work)
      ->excludes(only);  // options of the synthetic matrix alone
  return std::function<int()>([options, diligent_root] {
    try {
      if (!diligent_root->empty()) {
        const auto runs = bench::RunDiLiGenTBench(*diligent_root, options->out_dir);
        std::cout << "bench --diligent: " << runs.size() << " runs; " << (options->out_dir / "diligent.md").string() << "\n";
        return kExitOk;
      }
      options->executable = SelfExecutable("u3mscan");
      const auto rows = bench::RunBench(*options);
      int failed = 0;
      for (const auto& row : rows) failed += row.status == "ok" ? 0 : 1;
      std::cout << "bench: " << rows.size() << " runs (" << failed << " failed); " << (options->out_dir / "bench.md").string() << "\n";
      return failed ? kExitFailed : kExitOk;
    } catch (const InputError& e) {
      std::cerr << "error: " << e.what() << "\n";
      return kExitUsage;
    }
  });
});

}  // namespace
}  // namespace u3mscan::cli

#!/usr/bin/env bash
# The main job on a fresh machine: installs what is missing, builds, and runs u3mscan's main job.
# Today: writes a complete example U3M from built-in values into out/example/ and validates it.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/install-deps.sh
tools/build.sh --target u3mscan
build_dir=${U3MSCAN_BUILD_DIR:-build}
out=${1:-out}
"$build_dir/cli/u3mscan" example -o "$out/example"
"$build_dir/cli/u3mscan" validate "$out/example/example.u3m"
echo "Wrote $out/example/example.u3m (textures in $out/example/textures/)"

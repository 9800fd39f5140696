#!/usr/bin/env bash
# The main job on a fresh machine: installs what is missing, builds, renders a synthetic capture
# (a twill under near point lights, with every calibration frame) and processes it into a U3M.
# Usage: tools/run.sh [OUT]   (default OUT = out)
set -euo pipefail
cd "$(dirname "$0")/.."
tools/install-deps.sh
tools/build.sh --target u3mscan
build_dir=${U3MSCAN_BUILD_DIR:-build}
u3mscan="$build_dir/cli/u3mscan"
out=${1:-out}
rm -rf "$out/twill-synthetic"
"$u3mscan" synth --scene twill --rig near --size 256x256 --seed 1 -o "$out/twill-synthetic"
"$u3mscan" process "$out/twill-synthetic/capture" -o "$out/twill" --name twill --debug-maps
"$u3mscan" validate "$out/twill/twill.u3m"
echo
echo "Material: $out/twill/twill.u3m (textures in $out/twill/textures/)"
echo "Report:   $out/twill/report.html"
echo "Truth:    $out/twill-synthetic/truth/ (compare with: $u3mscan evaluate $out/twill $out/twill-synthetic/truth)"

#!/usr/bin/env bash
# Installs exactly the Debian 12 packages u3mscan needs that are not there yet.
# Idempotent and quiet when everything is installed. Needs root (or sudo) only when
# something is missing. Nothing is downloaded from anywhere but Debian's archive.
set -euo pipefail

packages=(
  build-essential cmake ccache pkg-config
  libeigen3-dev libceres-dev libgoogle-glog-dev
  libopencv-dev libopencv-contrib-dev
  libopenimageio-dev openimageio-tools libopenexr-dev libraw-dev libtiff-dev zlib1g-dev
  nlohmann-json3-dev libcli11-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  python3 python3-jsonschema
  parallel
  clang libclang-rt-14-dev libomp-dev
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "install-deps: installing ${missing[*]}" >&2
sudo_cmd=()
[ "$(id -u)" -ne 0 ] && sudo_cmd=(sudo)
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null

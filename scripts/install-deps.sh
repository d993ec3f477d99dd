#!/usr/bin/env bash
# Installs the Debian packages tofcam needs, idempotently: prints what it installs, does nothing
# when everything is present, uses sudo when not root.
set -euo pipefail
packages=(
  build-essential cmake pkg-config lld
  libeigen3-dev libembree-dev libyaml-cpp-dev libcli11-dev nlohmann-json3-dev
  libpng-dev libcairo2-dev libhdf5-dev zlib1g-dev libtinyobjloader-dev libnanoflann-dev
  cyclonedds-dev cyclonedds-tools
  libgtest-dev libgmock-dev libbenchmark-dev
  clang libclang-rt-14-dev clang-format clang-tidy
  python3-dev python3-numpy python3-matplotlib python3-pytest pybind11-dev
  libcpp-httplib-dev libjs-three chromium python3-websocket
)
missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "deps: all ${#packages[@]} Debian packages present"
  exit 0
fi
sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
echo "deps: installing ${missing[*]}"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "deps: done"

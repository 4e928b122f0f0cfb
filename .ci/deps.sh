#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Install the Debian packages vafm needs, only those that are missing. Idempotent; used by `make`.
# `deps.sh --deb` adds the Debian packaging tools (`make deb` only: `make test` does not need them).
set -eu
pkgs=(meson ninja-build gcc pkg-config libjansson-dev python3 libhdf5-dev hdf5-tools python3-h5py python3-numpy libzmq3-dev python3-zmq
      python3-pytest libgsl-dev python3-matplotlib python3-scipy libopenmpi-dev openmpi-bin help2man)
if [ "${1:-}" = --deb ]; then pkgs+=(build-essential debhelper dh-python dpkg-dev fakeroot lintian); fi
missing=()
for p in "${pkgs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "installing Debian packages: ${missing[*]}" >&2
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"

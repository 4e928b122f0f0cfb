#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Install the Debian packages vafm needs, only those that are missing. Idempotent; used by `make`.
# `deps.sh --deb` adds the Debian packaging tools (`make deb` only: `make test` does not need them).
set -eu
pkgs=(meson ninja-build gcc pkg-config libjansson-dev python3 libhdf5-dev hdf5-tools python3-h5py python3-numpy libzmq3-dev python3-zmq
      python3-pytest libgsl-dev python3-matplotlib python3-scipy libopenmpi-dev openmpi-bin help2man
      python3-aiohttp nodejs chromium chromium-driver python3-selenium)
# npm: Debian's package, unless a nodejs that bundles its own npm is installed (then Debian's npm conflicts)
command -v npm >/dev/null 2>&1 || pkgs+=(npm)
if [ "${1:-}" = --deb ]; then pkgs+=(build-essential debhelper dh-python dpkg-dev fakeroot lintian); fi
missing=()
for p in "${pkgs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# the web panel's charting library (uPlot, pinned by clients/web/package-lock.json) from the npm registry
web_js() {
    local here; here="$(cd "$(dirname "$0")/.." && pwd)/clients/web"
    [ "$(cd "$here" && node -p "try { require('./node_modules/uplot/package.json').version ===
        require('./package.json').dependencies.uplot } catch (e) { false }" 2>/dev/null)" = true ] && return 0
    (cd "$here" && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error)
}
if [ ${#missing[@]} -eq 0 ]; then web_js; exit 0; fi
echo "installing Debian packages: ${missing[*]}" >&2
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
web_js

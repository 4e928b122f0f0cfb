#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# `make deb`: vafm's Debian packages, built outside the source tree. The tree's files (git's tracked and new
# ones, or without git everything but build directories) are copied to DEB_DIR/vafm-VERSION, where
# dpkg-buildpackage builds; it writes the .debs and the .changes to DEB_DIR. Then lintian (an error fails,
# warnings are printed) and tests/test_deb.sh on DEB_DIR. Usage: .ci/deb.sh DEB_DIR.
set -eu
cd "$(dirname "$0")/.."
DEB=${1:?usage: .ci/deb.sh DEB_DIR}
VERSION=$(dpkg-parsechangelog -S Version | sed 's/-[^-]*$//')
SRC=$DEB/vafm-$VERSION
case $DEB in /|.|..|./) echo "deb.sh: refusing to use $DEB as the output directory" >&2; exit 2 ;; esac
rm -rf "$DEB"
mkdir -p "$SRC"
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    # tracked files (as in the work tree, uncommitted changes included) and new files not ignored
    git ls-files -z --cached --others --exclude-standard |
        while IFS= read -r -d '' f; do [ -e "$f" ] && printf '%s\0' "$f"; done |
        tar --null --no-recursion -T - -cf - | tar -xf - -C "$SRC"
else
    tar --exclude='./build*' --exclude='./obj-*' --exclude="./$DEB" -cf - . | tar -xf - -C "$SRC"
fi
# uPlot for the web panel (npm ci, .ci/deps.sh; git ignores node_modules): meson installs it into the vafm package
[ -s clients/web/node_modules/uplot/dist/uPlot.iife.min.js ] ||
    { echo "deb.sh: clients/web/node_modules/uplot is missing: run bash .ci/deps.sh --deb (npm ci)" >&2; exit 1; }
tar -cf - clients/web/node_modules/uplot | tar -xf - -C "$SRC"
echo "deb: building in $SRC" >&2
(cd "$SRC" && nice dpkg-buildpackage -b -us -uc -j2)
# lintian: errors fail `make deb`. What it says and is left as it is (lintian 2.116, Debian 12):
#   W initial-upload-closes-no-bugs (each package): a first changelog entry closes no Debian bug (an ITP);
#     these packages are vafm's own, not an upload to Debian.
#   I no-symbols-control-file (libvafm0): no debian/*.symbols; the shlibs pin vafm's programs to the 0.x
#     API they were built with (debian/rules), which a symbols file would not add to while the API is 0.x.
#   I package-supports-alternative-init-but-no-init.d-script (vafm): a systemd unit, no SysV init script.
echo "deb: lintian" >&2
nice lintian -I --fail-on error "$DEB"/*.changes
bash tests/test_deb.sh "$DEB"
ls -l "$DEB"/*.deb

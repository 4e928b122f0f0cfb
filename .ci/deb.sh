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
echo "deb: building in $SRC" >&2
(cd "$SRC" && nice dpkg-buildpackage -b -us -uc -j2)
echo "deb: lintian" >&2
nice lintian -I --fail-on error "$DEB"/*.changes
bash tests/test_deb.sh "$DEB"
ls -l "$DEB"/*.deb

#!/usr/bin/env bash
# Installs the Debian packages listed in ci/debian-packages.txt that are missing, so that
# the peer-equality tests run instead of skipping. Needs root and apt-get; without them it
# names the missing packages (the tests that need them skip, naming them) and goes on.
set -uo pipefail
cd "$(dirname "$0")/.."
mapfile -t wanted < <(grep -vE '^\s*(#|$)' ci/debian-packages.txt)
missing=()
for pkg in "${wanted[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" \
        || missing+=("$pkg")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null; then
    echo "ci/install-test-packages.sh: not installed (needs root and apt-get): ${missing[*]};" \
         "the tests that use them will be skipped" >&2
    exit 0
fi
export DEBIAN_FRONTEND=noninteractive
if ! { apt-get update -qq >/dev/null && \
       apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null; }; then
    echo "ci/install-test-packages.sh: apt-get could not install: ${missing[*]};" \
         "the tests that use them will be skipped" >&2
fi
exit 0

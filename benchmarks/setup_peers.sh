#!/usr/bin/env bash
# Installs the peers the benchmarks compare lidarstat with (not needed by the library or
# the tests): Debian packages for CloudCompare and CGAL, PyPI packages through the
# `bench` extra (CSF, pysmrf for SMRF, ...). Run from the repository root as root (CI images and this project's
# machines are Debian bookworm).
set -euo pipefail
cd "$(dirname "$0")/.."
if command -v apt-get >/dev/null; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
        cloudcompare xvfb libcgal-dev libeigen3-dev g++ libusb-1.0-0 >/dev/null  # open3d needs libusb
fi
python -m pip install -q -e ".[bench]"

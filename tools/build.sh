#!/bin/sh
# Configures and builds vdbturb into ./build (Release, Ninja, ccache when present). Two jobs by default:
# OpenVDB's headers make each heavy translation unit use about 1.5 GB of memory.
set -eu
cd "$(dirname "$0")/.."
JOBS="${JOBS:-2}"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release
cmake --build build -j "$JOBS"

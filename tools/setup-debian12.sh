#!/bin/sh
# Installs everything vdbturb needs to build, test and run its demo on Debian 12, as root.
# Idempotent: packages already present are left alone. clang-14 and libfuzzer-14-dev serve bench/fuzz.sh only;
# slurm-wlm and munge the one-node Slurm cluster test of `vdbturb farm` (tests/farm/farm_test.sh); gnuplot-nox draws
# `vdbturb measure --plot`'s figures; libnanovdb-dev NanoVDB output (header-only), libnanovdb-tools the nanovdb_print and
# nanovdb_validate its tests run on the files written. blender (Debian's 3.4, about 1-2 minutes to install) runs the
# add-on's test (tests/blender/test_addon.py, ctest blender_addon) and the blender-* benchmarks (bench/blender_pairs.sh).
# openimageio-tools is not used, but Debian's OpenImageIOConfig.cmake names its binaries and fails to configure
# without them when packages come without their recommends.
# python3-dev, pybind11-dev and python3-numpy build and test the Python module (docs/python.md).
#   tools/setup-debian12.sh          build, test and demo
#   tools/setup-debian12.sh --bench  the same (Blender was once installed for the benchmarks only; kept for scripts)
set -eu
PACKAGES="g++ cmake ninja-build ccache pkg-config make git python3-dev pybind11-dev python3-pybind11 python3-numpy
  libopenvdb-dev libboost-iostreams-dev libtbb-dev libeigen3-dev libflann-dev liblz4-dev libblosc-dev
  libgtest-dev libgmock-dev libcli11-dev nlohmann-json3-dev libfftw3-dev
  libopenimageio-dev openimageio-tools libopencv-dev fonts-dejavu-core gnuplot-nox libnanovdb-dev libnanovdb-tools
  clang-14 libfuzzer-14-dev python3 python3-openvdb slurm-wlm munge blender"
case "${1:-}" in
--bench | "") ;;
*) echo "usage: $0 [--bench]" >&2; exit 2 ;;
esac
missing=""
for p in $PACKAGES; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  echo "setup: installing$missing"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q
  # shellcheck disable=SC2086
  apt-get install -y -q --no-install-recommends $missing
else
  echo "setup: all packages present"
fi

#!/bin/sh
# Build libfive's core library and lfmesh in a work folder outside the repository (nothing of it is kept
# here): sh build.sh WORK, with libfive's source in WORK/src (a clone of github.com/libfive/libfive;
# measured with e8370983e7bc, 2025-07-23). Debian: libeigen3-dev libboost-dev libpng-dev cmake g++.
# libfive's CMake adds -march=native: build on the machine that runs the benchmark. Then run the
# benchmark with LFMESH=WORK/lfmesh and --libfive pointing at this folder.
set -e
HERE=$(cd "$(dirname "$0")" && pwd)
WORK=$(cd "$1" && pwd)
mkdir -p "$WORK/build" && cd "$WORK/build"
cmake ../src -DBUILD_STUDIO_APP=OFF -DBUILD_GUILE_BINDINGS=OFF -DBUILD_PYTHON_BINDINGS=OFF -DBUILD_TESTS=OFF \
      -DENABLE_DEBUG=OFF -DCMAKE_BUILD_TYPE=Release
make -j2 libfive
g++ -std=c++17 -O3 -march=native -DEIGEN_NO_DEBUG -I "$WORK/src/libfive/include" -I /usr/include/eigen3 \
    "$HERE/lfmesh.cpp" -o "$WORK/lfmesh" -L "$WORK/build/libfive/src" -lfive \
    -Wl,-rpath,"$WORK/build/libfive/src" -lpthread

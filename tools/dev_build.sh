#!/usr/bin/env bash
# Developer build: compiles the extension modules into build/dev and copies them into
# python/calibproj, so that `PYTHONPATH=python python -m pytest` runs the working tree.
# Serialised with a lock, so several shells can call it at once.
set -euo pipefail
cd "$(dirname "$0")/.."
exec 9>build/.dev_build.lock 2>/dev/null || { mkdir -p build; exec 9>build/.dev_build.lock; }
flock 9
pybind11_dir=$(python3 -c 'import pybind11; print(pybind11.get_cmake_dir())')
if [ ! -f build/dev/CMakeCache.txt ]; then
  cmake -S . -B build/dev -G Ninja -DCMAKE_BUILD_TYPE=Release -DCALIBPROJ_BUILD_PYTHON=ON \
    -Dpybind11_DIR="$pybind11_dir" -DPython_EXECUTABLE="$(command -v python3)" > /dev/null
fi
cmake --build build/dev "$@"
# Copy, then rename: a test that imports the module meanwhile sees the old or the new
# file, never one half-written by the linker.
for module in build/dev/_*.so; do
  target="python/calibproj/$(basename "$module")"
  cp "$module" "$target.tmp"
  mv -f "$target.tmp" "$target"
done

#!/usr/bin/env bash
# Configures (Release by default) and builds into build/. BUILD_TYPE and BUILD_DIR override.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
# ccache keyed on paths relative to the checkout: another clone of the same sources (CI's fresh
# one) hits the cache instead of rebuilding everything.
export CCACHE_BASEDIR="$PWD" CCACHE_NOHASHDIR=1
BUILD_DIR=${BUILD_DIR:-build}
BUILD_TYPE=${BUILD_TYPE:-Release}
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE="$BUILD_TYPE" >/dev/null
cmake --build "$BUILD_DIR" -j"${JOBS:-2}"

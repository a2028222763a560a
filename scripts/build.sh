#!/usr/bin/env bash
# Configures and builds bitfuse into build/ (or $BUILD_DIR), Release with
# debug info, warnings as errors (BITFUSE_WERROR: on here and in CI, off
# for everyone else). Extra arguments go to cmake's configure step.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBITFUSE_WERROR=ON "$@" >/dev/null
cmake --build "$BUILD_DIR" -j "$(nproc)"

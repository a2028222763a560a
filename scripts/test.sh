#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test but those labelled
# `open` (requirements of an open issue not met yet; listed at the end):
#  1. the normal build, all tests (GPU tests with the Vulkan validation layer
#     on: any validation message fails them);
#  2. an AddressSanitizer + UBSan build, all tests again (the GPU tests keep
#     the validation layer loaded so LeakSanitizer can name, and suppress,
#     only that layer's own leaks: see docs/gpu.md).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
(cd build && ctest --output-on-failure -j 2 -LE open)
BUILD_DIR=build-asan bash scripts/build.sh -DBITFUSE_SANITIZE=ON
(cd build-asan && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
   ctest --output-on-failure -j 2 -LE open)
# Tests labelled `open` check requirements of open issues that the code does
# not meet yet (ctest -L open runs them); they are listed, not run, here.
echo "not run (label open, known to fail until their issue is done):"
(cd build && ctest -N -L open | grep 'Test *#' || true)

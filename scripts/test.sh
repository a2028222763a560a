#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test:
#  1. the normal build, all tests (GPU tests with the Vulkan validation layer
#     on: any validation message fails them);
#  2. an AddressSanitizer + UBSan build, the CPU-side tests (label "gpu"
#     excluded: the Vulkan driver is not ASan-clean).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
(cd build && ctest --output-on-failure -j 2)
BUILD_DIR=build-asan bash scripts/build.sh -DBITFUSE_SANITIZE=ON
(cd build-asan && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
   ctest --output-on-failure -j 2 -LE gpu)

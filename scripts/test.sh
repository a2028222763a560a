#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test:
#  1. the module table of docs/DESIGN.md against the #include lines;
#  2. the normal build, all tests (GPU tests with the Vulkan validation layer
#     on: any validation message fails them);
#  3. an AddressSanitizer + UBSan build, all tests again (the GPU tests keep
#     the validation layer loaded so LeakSanitizer can name, and suppress,
#     only that layer's own leaks: see docs/gpu.md); tests labelled
#     gpu_bound (their time is lavapipe's, their host code is covered by
#     other sanitized tests) run in the normal build only, for CI's 20 minutes;
#  4. every fuzz target (tests/fuzz/, docs/fuzz.md) for 20 s under ASan +
#     UBSan, two at a time: no crash, leak or hang may come up.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
python3 scripts/check-deps.py
bash scripts/build.sh
(cd build && ctest --output-on-failure -j 2)
BUILD_DIR=build-asan bash scripts/build.sh -DBITFUSE_SANITIZE=ON
(cd build-asan && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
   ctest --output-on-failure -j 2 -LE gpu_bound)
bash scripts/fuzz.sh 20 --jobs 2 --no-doc --seed 1

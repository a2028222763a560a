#!/usr/bin/env bash
# Installs what is missing, builds, and runs `bitfuse demo` on built-in
# synthetic data (output in out/demo, replaced on each run: bitfuse demo
# itself does not write over an earlier run's folder).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
rm -rf out/demo
./build/app/bitfuse demo --out out/demo "$@"

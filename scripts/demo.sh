#!/usr/bin/env bash
# Installs what is missing, builds, and runs `bitfuse demo` on built-in
# synthetic data (output in out/demo).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
./build/app/bitfuse demo --out out/demo "$@"

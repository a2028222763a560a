#!/usr/bin/env bash
# Installs what is missing, builds, and runs `bitfuse demo` on built-in
# synthetic data (output in out/demo, replaced on each run: bitfuse demo
# itself does not write over an earlier run's folder).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
# (only the default folder: an --out given on the command line is the user's)
case " $* " in *" --out "* | *" --out="*) ;; *) rm -rf out/demo ;; esac
./build/app/bitfuse demo --out out/demo "$@"

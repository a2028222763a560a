#!/usr/bin/env bash
# A packager's configure: `cmake -DCMAKE_BUILD_TYPE=Release` with nothing
# else must not make warnings errors (another compiler or -O3 may warn where
# CI's does not); BITFUSE_WERROR=ON, as scripts/build.sh sets it, must.
# Configure only (a few seconds); the builds themselves: scripts/build-types.sh.
# Usage: test_build_options.sh SOURCE_DIR
set -u
SRC=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
cmake -S "$SRC" -B "$T/b" -DCMAKE_BUILD_TYPE=Release >"$T/log" 2>&1 || { tail -c 2000 "$T/log"; exit 1; }
grep -q "BITFUSE_WERROR:BOOL=OFF" "$T/b/CMakeCache.txt" || fail "BITFUSE_WERROR is not off by default"
grep -rq -- "-Werror" "$T/b/core/CMakeFiles/bf_core.dir/flags.make" &&
    fail "a default Release configure compiles with -Werror: $(grep C_FLAGS "$T/b/core/CMakeFiles/bf_core.dir/flags.make")"
grep -q -- "-DBITFUSE_WERROR=ON" "$SRC/scripts/build.sh" || fail "scripts/build.sh (CI's build) does not turn BITFUSE_WERROR on"
[ $fails = 0 ] && echo "build option checks passed"
[ $fails = 0 ]

#!/usr/bin/env bash
# Builds every build type a packager may choose (Release, Debug,
# RelWithDebInfo) with gcc and, when installed, clang, warnings as errors,
# each into build-types/COMPILER-TYPE. Not part of scripts/test.sh (CI's
# 20 minutes); run it before a release or after a compiler upgrade.
set -euo pipefail
cd "$(dirname "$0")/.."
compilers="gcc"
command -v clang >/dev/null && compilers="gcc clang"
for cc in $compilers; do
    cxx=g++
    [ "$cc" = clang ] && cxx=clang++
    for type in Release Debug RelWithDebInfo; do
        dir=build-types/$cc-$type
        echo "== $cc $type"
        CC=$cc CXX=$cxx cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=$type -DBITFUSE_WERROR=ON >/dev/null
        cmake --build "$dir" -j "$(nproc)" >"$dir.log" 2>&1 || { tail -n 40 "$dir.log"; exit 1; }
    done
done
echo "every build type built without a warning"

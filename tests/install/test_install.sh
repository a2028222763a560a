#!/usr/bin/env bash
# cmake --install as a packager runs it, then a program built against the
# installed copy, not the source tree: examples/fuse_frames through the CMake
# package (find_package(bitfuse)), run on 2 frames of a tiny sequence made
# by the installed bitfuse, and through pkg-config, run on a missing input.
# Usage: test_install.sh BUILD_DIR SOURCE_DIR
set -u
BUILD=$1
SRC=$2
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
command -v pkg-config >/dev/null || { echo "no pkg-config"; exit 77; }
P="$T/prefix" # (pkg-config splits its flags at spaces: no space in the prefix)

cmake --install "$BUILD" --prefix "$P" >"$T/install.log" 2>&1 || { cat "$T/install.log"; echo "FAIL: cmake --install"; exit 1; }
for f in bin/bitfuse lib/libbf_core.a lib/libbf_recon.a lib/libbf_shaders.a include/bitfuse/core/core.h \
    include/bitfuse/recon/recon.h include/bitfuse/shaders/fusion.glsl.h lib/pkgconfig/bitfuse.pc \
    lib/cmake/bitfuse/bitfuseConfig.cmake lib/cmake/bitfuse/bitfuseConfigVersion.cmake; do
    [ -e "$P/$f" ] || fail "not installed: $f"
done
# Nothing of the source or build tree is needed: move the source's headers
# out of reach by building from a copy of the example alone.
cp -r "$SRC/examples/fuse_frames" "$T/example"

"$P/bin/bitfuse" --version >"$T/version" 2>&1 || fail "installed bitfuse --version: $(cat "$T/version")"
printf '%s\n' "1000.0 0 0 0 0 0 0 1" "1000.1 0.01 0 0 0 0 0 1" "1000.2 0.02 0 0 0 0 0 1" >"$T/traj.txt"
"$P/bin/bitfuse" synth --trajectory "$T/traj.txt" --frames 2 --size 80x60 --camera 65.6,65.6,39.5,29.5 \
    --data "$T" --out "$T/seq" >"$T/synth.log" 2>&1 || fail "installed bitfuse synth: $(tail -c 400 "$T/synth.log")"

# 1. CMake package.
if cmake -S "$T/example" -B "$T/b-cmake" -DCMAKE_PREFIX_PATH="$P" -DCMAKE_BUILD_TYPE=Release >"$T/cmake.log" 2>&1 &&
    cmake --build "$T/b-cmake" >>"$T/cmake.log" 2>&1; then
    grep -q -- "-I$SRC\b\|$SRC/core" "$T/b-cmake/CMakeFiles/fuse_frames.dir/flags.make" &&
        fail "the CMake package points into the source tree"
    "$T/b-cmake/fuse_frames" "$T/seq" 2 >"$T/run.log" 2>&1 || fail "fuse_frames (CMake): $(tail -c 400 "$T/run.log")"
    grep -q "^fuse_frames: 2 frames fused" "$T/run.log" || fail "fuse_frames (CMake) did not fuse 2 frames: $(cat "$T/run.log")"
else
    fail "the example does not build with find_package(bitfuse): $(tail -c 1500 "$T/cmake.log")"
fi

# 2. pkg-config (version and a plain compiler line).
export PKG_CONFIG_PATH="$P/lib/pkgconfig"
[ "$(pkg-config --modversion bitfuse)" = "$(cut -d' ' -f2 "$T/version")" ] ||
    fail "bitfuse.pc's version $(pkg-config --modversion bitfuse) is not the program's $(cat "$T/version")"
# (The same program as above; it runs here on a missing input, the library's
# status named, to keep the test short.)
if cc -o "$T/fuse_frames_pc" "$T/example/fuse_frames.c" $(pkg-config --cflags --libs bitfuse) >"$T/cc.log" 2>&1; then
    "$T/fuse_frames_pc" "$T/missing" >"$T/run.log" 2>&1 && fail "fuse_frames (pkg-config) on a missing sequence succeeded"
    grep -qF "$T/missing" "$T/run.log" || fail "fuse_frames (pkg-config) on a missing sequence: $(cat "$T/run.log")"
else
    fail "the example does not build with pkg-config --cflags --libs bitfuse: $(tail -c 1500 "$T/cc.log")"
fi

[ $fails = 0 ] && echo "install checks passed"
[ $fails = 0 ]

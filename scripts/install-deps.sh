#!/usr/bin/env bash
# Installs the Debian 12 packages bitfuse needs to build, run and test.
# Idempotent: skips apt-get when everything is already there. Run as root
# (or with sudo available).
set -euo pipefail

PACKAGES=(
  build-essential cmake pkg-config
  libvulkan-dev mesa-vulkan-drivers vulkan-validationlayers vulkan-tools glslc
  libpng-dev libjpeg-dev libzstd-dev libcjson-dev libxxhash-dev
  # Mesh simplification for export (mesh/simplify.c).
  libmeshoptimizer-dev
  # bitfuse calibrate (calib/) and eval-motion (eval/): OpenCV's calib3d,
  # features2d and video (Lucas-Kanade) and what they need, without
  # libopencv-dev, which brings every OpenCV module, VTK and Qt.
  libopencv-core-dev libopencv-imgproc-dev libopencv-calib3d-dev libopencv-features2d-dev libopencv-video-dev
  # Live capture backends (docs/devices.md); libfreenect-bin brings fakenect,
  # which the capture tests replay Kinect dumps through.
  libfreenect-dev libfreenect-bin libopenni2-dev
  python3 python3-numpy python3-matplotlib
  # The fuzz targets (scripts/fuzz.sh): clang and its libFuzzer runtime.
  clang libclang-rt-dev
  # The viewer window (view/: GLFW) and its test under a virtual X server.
  libglfw3-dev xvfb
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# The Khronos glTF validator for test_glb_validator (skipped without it),
# from the npm registry when node's package manager is there.
optional_npm() {
  if command -v npm >/dev/null && ! [ -d "$(npm root -g 2>/dev/null)/gltf-validator" ]; then
    echo "install-deps: npm install -g gltf-validator (optional, for test_glb_validator)"
    npm install -g gltf-validator >/dev/null 2>&1 || echo "install-deps: gltf-validator not installed (its test will skip)"
  fi
}

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

# lavapipe, the CPU Vulkan driver every run uses without a GPU, from Mesa 25
# (bookworm-backports, Debian's own) when bookworm's is older: Debian 12's
# Mesa 22.3 loads each storage-buffer word in a loop over the SIMD lanes, and
# its ray-casts run 1.4-3.5x faster on Mesa 25 with the same results
# (docs/gpu.md, "The driver"). Falls back to bookworm's Mesa when the
# backports archive cannot be reached.
MESA_MIN=25
mesa_recent() {
  local v
  v=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null) || return 1
  [ -n "$v" ] && dpkg --compare-versions "$v" ge "$MESA_MIN"
}
backports_mesa() {
  . /etc/os-release 2>/dev/null || return 0
  [ "${VERSION_CODENAME:-}" = bookworm ] || return 0
  mesa_recent && return 0
  if ! grep -rqs "bookworm-backports" /etc/apt/sources.list /etc/apt/sources.list.d/; then
    echo "deb http://deb.debian.org/debian bookworm-backports main" |
      $SUDO tee /etc/apt/sources.list.d/bookworm-backports.list >/dev/null
  fi
  echo "install-deps: Mesa $MESA_MIN+ (lavapipe) from bookworm-backports"
  if $SUDO apt-get update -q && $SUDO apt-get install -y -q --no-install-recommends \
      -t bookworm-backports mesa-vulkan-drivers; then
    return 0
  fi
  echo "install-deps: bookworm-backports not reachable; keeping Debian 12's Mesa (slower lavapipe)" >&2
}

if [ ${#missing[@]} -ne 0 ]; then
  echo "install-deps: installing ${missing[*]}"
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "install-deps: all ${#PACKAGES[@]} packages present"
fi
backports_mesa
optional_npm

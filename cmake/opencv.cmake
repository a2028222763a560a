include_guard(GLOBAL)
# OpenCV for the two C++ files that call it (calib/calib_cv.cpp,
# features/features_cv.cpp). Debian's split packages (libopencv-calib3d-dev,
# -features2d-dev, -imgproc-dev, -core-dev) ship no opencv4.pc: only
# libopencv-dev has it, and that one pulls every OpenCV module, VTK and Qt.
# So pkg-config's opencv4 is used where it exists, and otherwise the headers
# and the libraries are found directly; either way only the modules named
# are linked.
#   bf_opencv_libs(OUT_VAR module...)  e.g. bf_opencv_libs(libs core calib3d)
pkg_check_modules(OPENCV QUIET opencv4)
find_path(OPENCV_INCLUDE_DIR opencv2/calib3d.hpp HINTS ${OPENCV_INCLUDE_DIRS} PATH_SUFFIXES opencv4 REQUIRED)
function(bf_opencv_libs out)
  set(libs)
  foreach(m ${ARGN})
    find_library(OPENCV_${m}_LIBRARY opencv_${m} HINTS ${OPENCV_LIBRARY_DIRS} REQUIRED)
    list(APPEND libs ${OPENCV_${m}_LIBRARY})
  endforeach()
  set(${out} ${libs} PARENT_SCOPE)
endfunction()

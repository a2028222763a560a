# cmake --install (--prefix P): what a packager or a user building against
# bitfuse needs.
#   P/bin/bitfuse
#   P/lib/libbf_MODULE.a                     one static library per module
#   P/include/bitfuse/MODULE/MODULE.h        each module's one public header,
#   P/include/bitfuse/shaders/*.glsl.h       and the C/GLSL headers they share
#   P/lib/pkgconfig/bitfuse.pc               pkg-config --cflags --libs bitfuse
#   P/lib/cmake/bitfuse/bitfuseConfig.cmake  find_package(bitfuse): bitfuse::MODULE
#                                            and bitfuse::bitfuse (every module)
# tests/install/test_install.sh builds examples/fuse_frames against both.
include(CMakePackageConfigHelpers)

# Modules in link order (a library before the ones it uses; DESIGN.md
# section 2), the embedded shaders after the modules that run them.
set(BITFUSE_MODULES recon stream tracking render export fusion store synth eval features mesh hostmap replay
    calib capture gpu core)
install(TARGETS bitfuse RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
set(bitfuse_targets "")
foreach(m ${BITFUSE_MODULES})
  set_target_properties(bf_${m} PROPERTIES EXPORT_NAME ${m})
  list(APPEND bitfuse_targets bf_${m})
  install(FILES ${CMAKE_SOURCE_DIR}/${m}/${m}.h DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/bitfuse/${m})
endforeach()
set_target_properties(bf_shaders PROPERTIES EXPORT_NAME shaders)
list(APPEND bitfuse_targets bf_shaders)
file(GLOB shared_headers ${CMAKE_SOURCE_DIR}/shaders/*.glsl.h)
install(FILES ${shared_headers} DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/bitfuse/shaders)

# Every module at once: bitfuse::bitfuse.
add_library(bf_all INTERFACE)
set_target_properties(bf_all PROPERTIES EXPORT_NAME bitfuse)
foreach(m ${BITFUSE_MODULES})
  target_link_libraries(bf_all INTERFACE bf_${m})
endforeach()
list(APPEND bitfuse_targets bf_all)

install(TARGETS ${bitfuse_targets} EXPORT bitfuseTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
# bitfuse.pc: the libraries are static, so Libs names everything they use
# (OpenCV's libraries, which calib/ and features/ call, and meshoptimizer
# have no usable .pc on Debian; the C++ runtime for their C++ files).
set(pc_libs "")
foreach(m ${BITFUSE_MODULES})
  string(APPEND pc_libs " -lbf_${m}")
endforeach()
string(APPEND pc_libs " -lbf_shaders")
foreach(m calib3d features2d video imgproc core)
  set(lib ${OPENCV_${m}_LIBRARY})
  get_filename_component(dir ${lib} DIRECTORY)
  get_filename_component(name ${lib} NAME_WE)
  string(REGEX REPLACE "^lib" "" name ${name})
  string(FIND "${pc_libs}" " -L${dir} " at)
  if(at EQUAL -1)
    string(APPEND pc_libs " -L${dir}")
  endif()
  string(APPEND pc_libs " -l${name}")
endforeach()
string(APPEND pc_libs " -lmeshoptimizer -lstdc++ -lm -ldl -lpthread")
# The live backends capture/ was built with (their libraries are found the
# same way by bitfuseConfig.cmake).
set(pc_requires "vulkan libpng libjpeg libzstd libcjson libxxhash")
set(BITFUSE_HAVE_FREENECT ${FREENECT_FOUND})
set(BITFUSE_HAVE_OPENNI2 ${OPENNI2_FOUND})
if(FREENECT_FOUND)
  string(APPEND pc_requires " libfreenect")
endif()
if(OPENNI2_FOUND)
  string(APPEND pc_requires " libopenni2")
endif()
# The prefix relative to the .pc file, so `cmake --install --prefix P` and
# a moved copy both work.
file(RELATIVE_PATH pc_up /p/${CMAKE_INSTALL_LIBDIR}/pkgconfig /p)
string(REGEX REPLACE "/$" "" pc_up "${pc_up}")
configure_file(${CMAKE_SOURCE_DIR}/cmake/bitfuse.pc.in ${CMAKE_BINARY_DIR}/bitfuse.pc @ONLY)
install(FILES ${CMAKE_BINARY_DIR}/bitfuse.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)

set(cmake_dir ${CMAKE_INSTALL_LIBDIR}/cmake/bitfuse)
install(EXPORT bitfuseTargets NAMESPACE bitfuse:: DESTINATION ${cmake_dir})
configure_package_config_file(${CMAKE_SOURCE_DIR}/cmake/bitfuseConfig.cmake.in
                              ${CMAKE_BINARY_DIR}/bitfuseConfig.cmake INSTALL_DESTINATION ${cmake_dir})
write_basic_package_version_file(${CMAKE_BINARY_DIR}/bitfuseConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/bitfuseConfig.cmake ${CMAKE_BINARY_DIR}/bitfuseConfigVersion.cmake
        DESTINATION ${cmake_dir})

# `cmake --install` rules: the libraries, their headers and a package config,
# so that another project can
#   find_package(cashash REQUIRED)
#   target_link_libraries(app PRIVATE cashash::cashash)
# Everything here is in the "devel" component; the Python module installs
# its own component (python/CMakeLists.txt).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(CASHASH_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/cashash)

# Headers keep their folder names (cashash/, colmap_bridge/api/, cashash_cuda/)
# so that the same #include lines work in the tree and once installed.
set(CASHASH_EXPORTED_TARGETS cashash_core cashash_distributed cashash_bridge)
target_include_directories(cashash_core INTERFACE $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
if(CASHASH_WITH_CUDA)
  list(APPEND CASHASH_EXPORTED_TARGETS cashash_cuda)
endif()

# The one target users link: the CLI's name `cashash` is taken by the
# executable, so the interface target is exported under that name instead.
add_library(cashash_library INTERFACE)
target_link_libraries(cashash_library INTERFACE cashash_bridge)
set_target_properties(cashash_library PROPERTIES EXPORT_NAME cashash)
add_library(cashash::cashash ALIAS cashash_library)

install(TARGETS ${CASHASH_EXPORTED_TARGETS} cashash_library EXPORT cashashTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT devel
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT devel)
if(TARGET cashash)
  install(TARGETS cashash RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT devel)
endif()

install(DIRECTORY ${PROJECT_SOURCE_DIR}/src/cashash DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        COMPONENT devel FILES_MATCHING PATTERN "*.h")
# Only the bridge headers the library API needs; the database internals stay
# private.
install(FILES ${PROJECT_SOURCE_DIR}/colmap_bridge/api/matching_api.h ${PROJECT_SOURCE_DIR}/colmap_bridge/api/command_options.h
              ${PROJECT_SOURCE_DIR}/colmap_bridge/api/run_resolution.h
              ${PROJECT_SOURCE_DIR}/colmap_bridge/api/run_gpu_resources.h
        DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/colmap_bridge/api COMPONENT devel)
if(CASHASH_WITH_CUDA)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/cuda/cashash_cuda DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
          COMPONENT devel FILES_MATCHING PATTERN "*.h")
endif()

install(EXPORT cashashTargets NAMESPACE cashash:: DESTINATION ${CASHASH_INSTALL_CMAKEDIR} COMPONENT devel)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/cashashConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/cashashConfig.cmake
                              INSTALL_DESTINATION ${CASHASH_INSTALL_CMAKEDIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/cashashConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/cashashConfig.cmake ${PROJECT_BINARY_DIR}/cashashConfigVersion.cmake
        DESTINATION ${CASHASH_INSTALL_CMAKEDIR} COMPONENT devel)

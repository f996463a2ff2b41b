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

# The headers of the library API (README.md, "For C++") and every header of
# this project they include, found by following their #include "..." lines
# at configure time; the pipeline's and the database's internals that no
# API header includes stay private. cashash_cuda/ headers are installed
# below.
set(CASHASH_API_HEADERS
    colmap_bridge/api/matching_api.h colmap_bridge/api/command_options.h colmap_bridge/api/run_resolution.h
    colmap_bridge/api/run_gpu_resources.h cashash/matching/pair_matching.h)

# Sets `out` to `headers` and the project headers they include, transitively
# (paths as included: cashash/..., colmap_bridge/..., cashash_cuda/...).
function(cashash_included_headers out)
  set(pending ${ARGN})
  set(found)
  while(pending)
    list(POP_FRONT pending header)
    if(header IN_LIST found)
      continue()
    endif()
    set(path)
    foreach(root ${PROJECT_SOURCE_DIR}/src ${PROJECT_SOURCE_DIR}/cuda ${PROJECT_SOURCE_DIR})
      if(NOT path AND EXISTS ${root}/${header})
        set(path ${root}/${header})
      endif()
    endforeach()
    if(NOT path)
      continue()  # a system or third-party header
    endif()
    list(APPEND found ${header})
    set_property(DIRECTORY ${PROJECT_SOURCE_DIR} APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${path})
    file(STRINGS ${path} include_lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
    foreach(line ${include_lines})
      string(REGEX REPLACE "^[^\"]*\"([^\"]+)\".*$" "\\1" included "${line}")
      list(APPEND pending ${included})
    endforeach()
  endwhile()
  set(${out} ${found} PARENT_SCOPE)
endfunction()

cashash_included_headers(CASHASH_INSTALLED_HEADERS ${CASHASH_API_HEADERS})
foreach(header ${CASHASH_INSTALLED_HEADERS})
  if(header MATCHES "^cashash_cuda/")
    continue()
  endif()
  get_filename_component(header_dir ${header} DIRECTORY)
  set(header_root ${PROJECT_SOURCE_DIR})
  if(header MATCHES "^cashash/")
    set(header_root ${PROJECT_SOURCE_DIR}/src)
  endif()
  install(FILES ${header_root}/${header} DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/${header_dir} COMPONENT devel)
endforeach()
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

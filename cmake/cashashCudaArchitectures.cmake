# The CUDA architectures of the GPU backend (README, "GPU architectures").
# Included after enable_language(CUDA). Sets CMAKE_CUDA_ARCHITECTURES (the
# default of every CUDA target) and CASHASH_CUDA_ARCHITECTURES_BUILT, the
# resolved list that the binary reports (cashash --version).
#
#   CASHASH_CUDA_ARCHITECTURES set:  that list (CMake syntax: "86",
#       "75-real;90", "80-virtual", "native"), or "portable".
#   unset, a GPU found at configure:  that GPU's SASS (CMake's `native`).
#   unset, no GPU (CI, containers):   the portable list.
#
# The portable list is SASS for compute capability 7.5 (T4, RTX 20), 8.0
# (A100), 8.6 (RTX 30, A10), 8.9 (RTX 40, L4) and 9.0 (H100, H200), plus the
# PTX of 9.0, which newer cards (Blackwell) compile when the program loads.
# CUDA 13 compiles nothing older than 7.5, and the kernels need 7.5 (int8
# mma, ldmatrix).
set(CASHASH_CUDA_PORTABLE_ARCHITECTURES "75-real;80-real;86-real;89-real;90")

set(_cashash_arch "${CASHASH_CUDA_ARCHITECTURES}")
if(_cashash_arch STREQUAL "portable")
  set(_cashash_arch "${CASHASH_CUDA_PORTABLE_ARCHITECTURES}")
  set(_cashash_arch_why "portable list (CASHASH_CUDA_ARCHITECTURES=portable)")
elseif(_cashash_arch STREQUAL "")
  # GPUs older than 7.5 cannot run the kernels: they do not count.
  set(_cashash_native "")
  foreach(_cashash_gpu IN LISTS CMAKE_CUDA_ARCHITECTURES_NATIVE)
    string(REGEX MATCH "^[0-9]+" _cashash_number "${_cashash_gpu}")
    if(_cashash_number GREATER_EQUAL 75)
      list(APPEND _cashash_native "${_cashash_gpu}")
    endif()
  endforeach()
  if(_cashash_native)
    set(_cashash_arch "native")
    set(_cashash_arch_why "the GPU found at configure time")
  else()
    set(_cashash_arch "${CASHASH_CUDA_PORTABLE_ARCHITECTURES}")
    set(_cashash_arch_why "portable list: no GPU of compute capability 7.5 or newer found at configure time")
  endif()
else()
  set(_cashash_arch_why "CASHASH_CUDA_ARCHITECTURES")
endif()

# What the binary will carry, with CMake's keywords spelled out.
set(CASHASH_CUDA_ARCHITECTURES_BUILT "${_cashash_arch}")
if(_cashash_arch STREQUAL "native")
  set(CASHASH_CUDA_ARCHITECTURES_BUILT "${CMAKE_CUDA_ARCHITECTURES_NATIVE}")
  if(_cashash_native)
    # Only the GPUs the kernels can run on (a machine may hold older ones too).
    set(_cashash_arch "${_cashash_native}")
    set(CASHASH_CUDA_ARCHITECTURES_BUILT "${_cashash_native}")
  endif()
elseif(_cashash_arch STREQUAL "all" AND DEFINED CMAKE_CUDA_ARCHITECTURES_ALL)
  set(CASHASH_CUDA_ARCHITECTURES_BUILT "${CMAKE_CUDA_ARCHITECTURES_ALL}")
elseif(_cashash_arch STREQUAL "all-major" AND DEFINED CMAKE_CUDA_ARCHITECTURES_ALL_MAJOR)
  set(CASHASH_CUDA_ARCHITECTURES_BUILT "${CMAKE_CUDA_ARCHITECTURES_ALL_MAJOR}")
endif()

set(CMAKE_CUDA_ARCHITECTURES "${_cashash_arch}")
message(STATUS "cashash: CUDA architectures ${CASHASH_CUDA_ARCHITECTURES_BUILT} (${_cashash_arch_why})")
unset(_cashash_arch)
unset(_cashash_arch_why)
unset(_cashash_native)
unset(_cashash_gpu)
unset(_cashash_number)

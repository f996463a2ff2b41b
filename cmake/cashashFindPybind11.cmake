# cashash_find_pybind11(QUIET|REQUIRED): finds Python's interpreter and
# module headers and pybind11 (also one installed by pip and not registered
# with CMake); sets pybind11_FOUND.
macro(cashash_find_pybind11 mode)
  find_package(Python 3.8 ${mode} COMPONENTS Interpreter Development.Module)
  if(Python_FOUND)
    find_package(pybind11 2.10 CONFIG QUIET)
    if(NOT pybind11_FOUND)
      execute_process(COMMAND ${Python_EXECUTABLE} -m pybind11 --cmakedir
                      OUTPUT_VARIABLE CASHASH_PYBIND11_DIR OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
      find_package(pybind11 2.10 CONFIG ${mode} HINTS ${CASHASH_PYBIND11_DIR})
    endif()
  else()
    set(pybind11_FOUND FALSE)
  endif()
endmacro()

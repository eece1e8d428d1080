# fix_wheel_python_includes(): call after rosidl_generate_interfaces().
#
# The ros-jazzy-* wheels were built in a manylinux container: their exported
# *__rosidl_generator_py targets name that container's Python and NumPy include
# directories (/opt/python/cp...), which do not exist here. Point every such target
# imported in the calling directory at this interpreter's include directories.
function(fix_wheel_python_includes)
  find_package(Python3 REQUIRED COMPONENTS Interpreter Development NumPy)
  get_property(_imported DIRECTORY PROPERTY IMPORTED_TARGETS)
  foreach(_tgt IN LISTS _imported)
    if(_tgt MATCHES "__rosidl_generator_py$")
      get_target_property(_dirs ${_tgt} INTERFACE_INCLUDE_DIRECTORIES)
      if(_dirs)
        list(FILTER _dirs EXCLUDE REGEX "^/opt/python/cp")
        list(APPEND _dirs ${Python3_INCLUDE_DIRS} ${Python3_NumPy_INCLUDE_DIRS})
        set_target_properties(${_tgt} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_dirs}")
      endif()
    endif()
  endforeach()
endfunction()

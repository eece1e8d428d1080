# python_only_generators(): call after the find_package() calls and before rosidl_generate_interfaces().
#
# With -DQTREE_PYTHON_ONLY=ON (scripts/setup_env.sh sets it), the package is generated for rclpy only: the C
# generator, its type supports and the Python generator. The C++ generator and C++ type supports, which every
# rosidl package registers as it is found (rosidl_default_generators, and each message dependency's exported
# rosidl_typesupport_cpp), are dropped from the generate extension point: they are half the build's time and no
# node of this project is C++. Without the option (a colcon workspace, a C++ client) every generator runs.
option(QTREE_PYTHON_ONLY "generate the C and Python interfaces only (for rclpy)" OFF)
macro(python_only_generators)
  if(QTREE_PYTHON_ONLY)
    list(FILTER AMENT_EXTENSIONS_rosidl_generate_idl_interfaces EXCLUDE REGEX "_cpp:")
    message(STATUS "QTREE_PYTHON_ONLY: generators ${AMENT_EXTENSIONS_rosidl_generate_idl_interfaces}")
  endif()
endmacro()

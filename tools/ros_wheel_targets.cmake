# Included into the interface packages' builds by tools/build_interfaces.py (CMAKE_PROJECT_INCLUDE).
# The ROS 2 wheels export their Python-generator targets with the include directories of the
# machine that built them (/opt/python/...): CMake refuses to generate with a missing directory.
# At the end of the configure step, every imported target that names one is pointed at this
# venv's Python and NumPy headers (PYTHON_HEADER_DIRS, given by the script).
function(vplayground_fix_wheel_include_dirs)
  get_property(targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(target IN LISTS targets)
    get_target_property(dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
    if(dirs AND "${dirs}" MATCHES "^/opt/python/")
      set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${PYTHON_HEADER_DIRS}")
    endif()
  endforeach()
endfunction()
cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL vplayground_fix_wheel_include_dirs)

# MAVLink 2 C headers generated at build time by pymavlink's mavgen from the common.xml pymavlink
# ships (into the build tree; never committed). Defines the target `gainlink_mavlink_headers` and the
# variable GL_MAVLINK_GEN (the include directory holding common/mavlink.h).
# GL_MAVLINK_HEADERS: a folder already holding mavgen's output for that common.xml (gainlink's build driver
# generates it once per pymavlink version and shares it between builds); the build then uses it as it is.
include_guard(GLOBAL)

set(GL_MAVLINK_HEADERS "" CACHE PATH "Pre-generated MAVLink 2 C headers (holding common/mavlink.h); generated here when empty")
if(GL_MAVLINK_HEADERS)
  if(NOT EXISTS "${GL_MAVLINK_HEADERS}/common/mavlink.h")
    message(FATAL_ERROR "GL_MAVLINK_HEADERS (${GL_MAVLINK_HEADERS}) holds no common/mavlink.h")
  endif()
  set(GL_MAVLINK_GEN "${GL_MAVLINK_HEADERS}")
  add_custom_target(gainlink_mavlink_headers)
  return()
endif()

set(GL_PYTHON "" CACHE FILEPATH "Python interpreter with pymavlink (for mavgen); found automatically when empty")
if(NOT GL_PYTHON)
  get_filename_component(_gl_repo "${CMAKE_CURRENT_LIST_DIR}/../.." ABSOLUTE)
  if(EXISTS "${_gl_repo}/.venv/bin/python")
    set(GL_PYTHON "${_gl_repo}/.venv/bin/python")
  else()
    find_package(Python3 REQUIRED COMPONENTS Interpreter)
    set(GL_PYTHON "${Python3_EXECUTABLE}")
  endif()
endif()
execute_process(
  COMMAND "${GL_PYTHON}" -c "import os, pymavlink; print(os.path.join(os.path.dirname(pymavlink.__file__), 'dialects', 'v20', 'common.xml'))"
  OUTPUT_VARIABLE GL_MAVLINK_XML OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE _gl_rc)
if(NOT _gl_rc EQUAL 0 OR NOT EXISTS "${GL_MAVLINK_XML}")
  message(FATAL_ERROR "MAVLink: ${GL_PYTHON} cannot import pymavlink (set GL_PYTHON to an interpreter that can)")
endif()

set(GL_MAVLINK_GEN "${CMAKE_BINARY_DIR}/mavlink")
add_custom_command(
  OUTPUT "${GL_MAVLINK_GEN}/common/mavlink.h"
  COMMAND "${GL_PYTHON}" -m pymavlink.tools.mavgen --lang=C --wire-protocol=2.0 --output=${GL_MAVLINK_GEN} ${GL_MAVLINK_XML}
  DEPENDS "${GL_MAVLINK_XML}"
  COMMENT "mavgen: MAVLink 2 C headers from ${GL_MAVLINK_XML}"
  VERBATIM)
add_custom_target(gainlink_mavlink_headers DEPENDS "${GL_MAVLINK_GEN}/common/mavlink.h")

# The scheduled loop (included from CMakeLists.txt when GL_GAINS_DIR holds a scheduled artifact's export:
# gl_gains.h with GL_SCHEDULED 1 and gl_sched_gains.c; see include/gainlink/gl_sched.h).
#
# Targets (the same names as for an unscheduled artifact, so gainlink.firmware.build finds them):
#   gainlink_sched   static library libgainlink_loop.a: src/gl_sched.c and the generated tables gl_sched_default
#   host:      gainlink_host (shared, for Python ctypes: ports/host/gl_sched_host.c)
#   cortex-m*: gainlink_image (ELF + .bin/.hex/.map): replay and PIL over semihosting (ports/cortex-m/main_sched.c),
#              with GL_IMAGE_SERVE the MAVLink and slcan nodes on its UART (ports/cortex-m/sched-image.cmake)
# host, GL_APPS: the CAN node (apps/can) and the MAVLink node (apps/mavlink) on the scheduled law.
add_library(gainlink_sched STATIC src/gl_sched.c src/gl_fmaf.c "${GL_GAINS_DIR}/gl_sched_gains.c")
target_link_libraries(gainlink_sched PUBLIC gainlink_config)
target_compile_options(gainlink_sched PRIVATE -Wvla -Wshadow -Wstrict-prototypes)
# Shipped as the loop's static library (libgainlink_loop.a, as for an unscheduled artifact).
set_target_properties(gainlink_sched PROPERTIES OUTPUT_NAME gainlink_loop)

if(GL_TARGET STREQUAL "host")
  target_link_libraries(gainlink_sched PUBLIC m)
  add_library(gainlink_host SHARED ports/host/gl_sched_host.c)
  target_link_libraries(gainlink_host PRIVATE -Wl,--whole-archive gainlink_sched -Wl,--no-whole-archive m)
  target_link_options(gainlink_host PRIVATE -Wl,--no-undefined)
  # The CAN node runs the scheduled law too (apps/can/gl_can_law.h; sigma a measured output).
  if(GL_APPS AND EXISTS "${CMAKE_CURRENT_SOURCE_DIR}/apps/can/CMakeLists.txt")
    add_subdirectory(apps/can)
  endif()
  # The MAVLink node too (apps/mavlink/gl_mav_law.h; sigma a measured output or carried after the references).
  if(GL_APPS AND EXISTS "${CMAKE_CURRENT_SOURCE_DIR}/apps/mavlink/CMakeLists.txt")
    add_subdirectory(apps/mavlink)
  endif()
elseif(GL_TARGET IN_LIST GL_CORTEX_M_TARGETS)
  include("${CMAKE_CURRENT_SOURCE_DIR}/cmake/cortex-m-cpu.cmake")
  target_compile_options(gainlink_config INTERFACE ${GL_CPU_FLAGS})
  target_link_options(gainlink_config INTERFACE ${GL_CPU_FLAGS})
  include(ports/cortex-m/sched-image.cmake)
else()
  message(FATAL_ERROR "GL_TARGET must be host or one of ${GL_CORTEX_M_TARGETS} (got '${GL_TARGET}')")
endif()

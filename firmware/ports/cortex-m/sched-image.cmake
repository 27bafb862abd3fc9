# Cortex-M image of a scheduled artifact (included from cmake/scheduled.cmake): the scheduled loop fed through
# semihosting files (main_sched.c: replay and PIL). Boards and linking: board-image.cmake.
# With GL_IMAGE_SERVE (default; not on the micro:bit, whose 16 KiB do not hold the nodes beside the tables) the image
# also carries the MAVLink and slcan nodes on its UART, on the scheduled law: the same node libraries as the host
# apps (apps/mavlink, apps/can), which take the law from gl_gains.h. GL_IMAGE_SERVE OFF: the replay-only image that
# `replay --engine qemu` and PIL run.
include("${CMAKE_CURRENT_LIST_DIR}/board-image.cmake")
option(GL_IMAGE_SERVE "Carry the MAVLink and slcan nodes on the UART (boards with the RAM for them)" ON)
if(GL_BOARD STREQUAL "microbit")
  set(GL_IMAGE_SERVE OFF)
endif()
if(GL_IMAGE_SERVE)
  add_subdirectory(apps/mavlink)
  add_subdirectory(apps/can)
  gl_add_image(gainlink_image SOURCES main_sched.c serve.c serve_mavlink.c serve_slcan.c flash_semihost.c
               LIBS gainlink_mavlink_node gainlink_can_node gainlink_sched m)
  target_compile_definitions(gainlink_image PRIVATE GL_IMAGE_SERVE=1 GL_IMAGE_SERVE_MAVLINK=1)
else()
  gl_add_image(gainlink_image SOURCES main_sched.c LIBS gainlink_sched m)
endif()

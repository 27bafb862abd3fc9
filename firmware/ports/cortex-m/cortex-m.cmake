# Cortex-M image (included from firmware/CMakeLists.txt when GL_TARGET is a Cortex-M core): the float loop, replay
# and PIL over semihosting, and on boards with the RAM for them the MAVLink and slcan nodes on the UART. Boards and
# linking: board-image.cmake.
include("${CMAKE_CURRENT_LIST_DIR}/board-image.cmake")

# The MAVLink and slcan nodes (serve_*.c, apps/mavlink, apps/can) need ~9 KiB of RAM beyond the loop; the
# micro:bit's 16 KiB holds the loop, replay/PIL over semihosting and the UART banner, and for a fixed-point export
# (whose integer law is the one an M0 runs) the slcan node too, not the MAVLink node.
# GL_IMAGE_SERVE OFF builds the replay-only image (the loop, replay/PIL over semihosting, the UART banner): what
# `replay --engine qemu` and PIL run; it compiles in a third of the time of the serving one.
option(GL_IMAGE_SERVE "Carry the MAVLink and slcan nodes on the UART (boards with the RAM for them)" ON)
set(GL_IMAGE_SERVE_MAVLINK ${GL_IMAGE_SERVE})
if(GL_BOARD STREQUAL "microbit")
  set(GL_IMAGE_SERVE_MAVLINK OFF)
  if(NOT EXISTS "${GL_GAINS_DIR}/gl_fixed_gains.c")
    set(GL_IMAGE_SERVE OFF)
  endif()
endif()

# A fixed-point export's nodes both run the integer law (apps/can, apps/mavlink), from one fixed-point library, named
# here (cmake/gl_fixed.cmake): with the MAVLink node, its generic loop gainlink_fixed_generic (its gains all data, as
# an uploaded set needs), which the slcan node links too; without it (the micro:bit), the unrolled gainlink_fixed. Bit
# for bit the same law (tests/test_target_uart_fixed.py).
if(GL_IMAGE_SERVE_MAVLINK)
  set(GL_FIXED_STEP_LIB gainlink_fixed_generic)
else()
  set(GL_FIXED_STEP_LIB gainlink_fixed)
endif()
set(GL_IMAGE_SOURCES main.c gl_stream.c)
set(GL_IMAGE_LIBS gainlink_loop gainlink_gains m)
# The same MAVLink and CAN node libraries as the host apps (apps/mavlink, apps/can): no copy of protocol logic.
if(GL_IMAGE_SERVE_MAVLINK)
  add_subdirectory(apps/mavlink) # the node libraries the image carries on its UART
  add_subdirectory(apps/can)
  list(APPEND GL_IMAGE_SOURCES serve.c serve_mavlink.c serve_slcan.c flash_semihost.c)
  list(PREPEND GL_IMAGE_LIBS gainlink_mavlink_node gainlink_can_node)
elseif(GL_IMAGE_SERVE)
  add_subdirectory(apps/can)
  list(APPEND GL_IMAGE_SOURCES serve.c serve_slcan.c)
  list(PREPEND GL_IMAGE_LIBS gainlink_can_node)
endif()
gl_add_image(gainlink_image SOURCES ${GL_IMAGE_SOURCES} LIBS ${GL_IMAGE_LIBS})
if(GL_IMAGE_SERVE)
  target_compile_definitions(gainlink_image PRIVATE GL_IMAGE_SERVE=1)
endif()
if(GL_IMAGE_SERVE_MAVLINK)
  target_compile_definitions(gainlink_image PRIVATE GL_IMAGE_SERVE_MAVLINK=1)
endif()

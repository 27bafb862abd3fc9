# Cortex-M image (included from firmware/CMakeLists.txt when GL_TARGET is a Cortex-M core): the build's law
# (gl_law.h) fed through semihosting (replay and PIL, main.c), and on boards with the RAM for them the MAVLink and
# slcan nodes on the UART. Boards and linking: board-image.cmake.
include("${CMAKE_CURRENT_LIST_DIR}/board-image.cmake")

# The MAVLink and slcan nodes (serve_*.c, apps/mavlink, apps/can) need ~9 KiB of RAM beyond the law; the
# micro:bit's 16 KiB holds the law, replay/PIL over semihosting and the UART banner, and for an integer law (the law
# an M0 runs) the slcan node too, not the MAVLink node (gainlink.firmware.targets says so to the Python side).
# GL_IMAGE_SERVE OFF builds the replay-only image (the law, replay/PIL over semihosting, the UART banner): what
# `replay --engine qemu`, PIL and the instruction count run; it compiles in a third of the time of the serving one.
option(GL_IMAGE_SERVE "Carry the MAVLink and slcan nodes on the UART (boards with the RAM for them)" ON)
if(NOT GL_LAW_NODES) # another law than the export's (a baseline, cmake/law.cmake): the law alone
  set(GL_IMAGE_SERVE OFF)
endif()
set(GL_IMAGE_SERVE_MAVLINK ${GL_IMAGE_SERVE})
if(GL_BOARD STREQUAL "microbit")
  set(GL_IMAGE_SERVE_MAVLINK OFF)
  if(NOT GL_LAW_INTEGER)
    set(GL_IMAGE_SERVE OFF)
  endif()
endif()

# The image runs one variant of the law (cmake/law.cmake), and its nodes the same one: with the MAVLink node, the
# generic variant (an uploaded set may carry other shifts; bit for bit the unrolled one), which the slcan node then
# runs too; without it (the replay-only image, the micro:bit), the unrolled one. Its banner names it (variant=).
if(GL_IMAGE_SERVE_MAVLINK)
  set(GL_NODE_LAW gainlink_loop_generic)
else()
  set(GL_NODE_LAW gainlink_loop)
endif()
set(GL_IMAGE_SOURCES main.c gl_stream.c)
set(GL_IMAGE_LIBS ${GL_NODE_LAW} m)
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

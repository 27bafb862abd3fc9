# Cortex-M image (included from firmware/CMakeLists.txt when GL_TARGET is a Cortex-M core).
#
# Boards, one QEMU machine each (board file, linker script <board>.ld, the core it carries):
#   microbit       board_microbit.c     cortex-m0   nRF51822, 16 KiB RAM: no bus node on the UART (see below)
#   mps2-an385     board_mps2_an385.c   cortex-m3
#   mps2-an386     board_mps2_an386.c   cortex-m4   (default for cortex-m4)
#   netduinoplus2  board_netduinoplus2.c cortex-m4  STM32F405
#   mps2-an500     board_mps2_an500.c   cortex-m7
#   mps2-an505     board_mps2_an505.c   cortex-m33  Secure image, IoT Kit
#   mps3-an547     board_mps3_an547.c   cortex-m55  Secure image, SSE-300
# The MAVLink and slcan nodes (serve_*.c, apps/mavlink, apps/can) need ~9 KiB of RAM beyond the loop; the
# micro:bit's 16 KiB holds the loop, replay/PIL over semihosting and the UART banner, not the nodes
# (GL_IMAGE_SERVE OFF), and it reads the replay stream 8 records at a time instead of 64.
set(GL_BOARDS_cortex-m0 microbit)
set(GL_BOARDS_cortex-m3 mps2-an385)
set(GL_BOARDS_cortex-m4 mps2-an386 netduinoplus2)
set(GL_BOARDS_cortex-m7 mps2-an500)
set(GL_BOARDS_cortex-m33 mps2-an505)
set(GL_BOARDS_cortex-m55 mps3-an547)
list(GET GL_BOARDS_${GL_TARGET} 0 GL_DEFAULT_BOARD)

set(GL_BOARD "${GL_DEFAULT_BOARD}" CACHE STRING "QEMU board of the image (${GL_BOARDS_${GL_TARGET}})")
set_property(CACHE GL_BOARD PROPERTY STRINGS ${GL_BOARDS_${GL_TARGET}})
option(GL_SKIP_FPU_ENABLE "Test only: leave CPACR alone so the startup self-test must catch the disabled FPU" OFF)
if(NOT GL_BOARD IN_LIST GL_BOARDS_${GL_TARGET})
  message(FATAL_ERROR "GL_BOARD ${GL_BOARD} does not carry a ${GL_TARGET} (${GL_TARGET} boards: "
                      "${GL_BOARDS_${GL_TARGET}})")
endif()

# GL_IMAGE_SERVE OFF builds the replay-only image (the loop, replay/PIL over semihosting, the UART banner): what
# `replay --engine qemu` and PIL run; it compiles in a third of the time of the serving one.
option(GL_IMAGE_SERVE "Carry the MAVLink and slcan nodes on the UART (boards with the RAM for them)" ON)
if(GL_BOARD STREQUAL "microbit")
  set(GL_IMAGE_SERVE OFF)
  set(GL_IMAGE_MAX_BLOCK 8)
else()
  set(GL_IMAGE_MAX_BLOCK 64)
endif()

set(GL_PORT_DIR "${CMAKE_CURRENT_SOURCE_DIR}/ports/cortex-m")
string(REPLACE "-" "_" GL_BOARD_STEM "${GL_BOARD}")
set(GL_BOARD_SRC "${GL_PORT_DIR}/board_${GL_BOARD_STEM}.c")
set(GL_LINKER_SCRIPT "${GL_PORT_DIR}/${GL_BOARD}.ld")

set(GL_IMAGE_SOURCES startup.c semihost.c main.c gl_stream.c gl_clock.c gl_uart.c no_heap.c)
if(GL_BOARD MATCHES "^mps")
  list(APPEND GL_IMAGE_SOURCES gl_cmsdk_uart.c)
endif()
if(GL_IMAGE_SERVE)
  add_subdirectory(apps/mavlink) # the node libraries the image carries on its UART
  add_subdirectory(apps/can)
  list(APPEND GL_IMAGE_SOURCES serve.c serve_mavlink.c serve_slcan.c flash_semihost.c)
endif()
list(TRANSFORM GL_IMAGE_SOURCES PREPEND "${GL_PORT_DIR}/")

add_executable(gainlink_image ${GL_IMAGE_SOURCES} "${GL_BOARD_SRC}")
set_target_properties(gainlink_image PROPERTIES OUTPUT_NAME "gainlink_image" SUFFIX ".elf")
target_include_directories(gainlink_image PRIVATE "${GL_PORT_DIR}")
target_compile_definitions(gainlink_image PRIVATE GL_IMAGE_MAX_BLOCK=${GL_IMAGE_MAX_BLOCK})
if(GL_IMAGE_SERVE)
  # The same MAVLink and CAN node libraries as the host apps (apps/mavlink, apps/can): no copy of protocol logic.
  target_compile_definitions(gainlink_image PRIVATE GL_IMAGE_SERVE=1)
  target_link_libraries(gainlink_image PRIVATE gainlink_mavlink_node gainlink_can_node)
endif()
target_link_libraries(gainlink_image PRIVATE gainlink_loop gainlink_gains m)
if(GL_SKIP_FPU_ENABLE)
  target_compile_definitions(gainlink_image PRIVATE GL_SKIP_FPU_ENABLE=1)
endif()
target_link_options(gainlink_image PRIVATE "-L${GL_PORT_DIR}" "-T${GL_LINKER_SCRIPT}"
                    "-Wl,-Map=${CMAKE_CURRENT_BINARY_DIR}/gainlink_image.map")
set_target_properties(gainlink_image PROPERTIES LINK_DEPENDS "${GL_LINKER_SCRIPT}")
add_custom_command(TARGET gainlink_image POST_BUILD
  COMMAND "${CMAKE_OBJCOPY}" -O binary "$<TARGET_FILE:gainlink_image>" "${CMAKE_CURRENT_BINARY_DIR}/gainlink_image.bin"
  COMMAND "${CMAKE_OBJCOPY}" -O ihex "$<TARGET_FILE:gainlink_image>" "${CMAKE_CURRENT_BINARY_DIR}/gainlink_image.hex"
  VERBATIM)

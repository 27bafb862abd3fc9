# Cortex-M4F image (included from firmware/CMakeLists.txt when GL_TARGET is cortex-m4).
set(GL_BOARD "mps2-an386" CACHE STRING "mps2-an386 or netduinoplus2")
set_property(CACHE GL_BOARD PROPERTY STRINGS mps2-an386 netduinoplus2)
option(GL_SKIP_FPU_ENABLE "Test only: leave CPACR alone so the startup self-test must catch the disabled FPU" OFF)

set(GL_PORT_DIR "${CMAKE_CURRENT_SOURCE_DIR}/ports/cortex-m")
if(GL_BOARD STREQUAL "mps2-an386")
  set(GL_BOARD_SRC "${GL_PORT_DIR}/board_mps2_an386.c")
elseif(GL_BOARD STREQUAL "netduinoplus2")
  set(GL_BOARD_SRC "${GL_PORT_DIR}/board_netduinoplus2.c")
else()
  message(FATAL_ERROR "GL_BOARD must be mps2-an386 or netduinoplus2 (got '${GL_BOARD}')")
endif()
set(GL_LINKER_SCRIPT "${GL_PORT_DIR}/${GL_BOARD}.ld")

add_executable(gainlink_image "${GL_PORT_DIR}/startup.c" "${GL_PORT_DIR}/semihost.c" "${GL_PORT_DIR}/main.c"
                              "${GL_PORT_DIR}/gl_clock.c" "${GL_PORT_DIR}/gl_uart.c" "${GL_PORT_DIR}/serve.c"
                              "${GL_PORT_DIR}/serve_mavlink.c" "${GL_PORT_DIR}/serve_slcan.c"
                              "${GL_PORT_DIR}/flash_semihost.c" "${GL_PORT_DIR}/no_heap.c" "${GL_BOARD_SRC}")
set_target_properties(gainlink_image PROPERTIES OUTPUT_NAME "gainlink_image" SUFFIX ".elf")
target_include_directories(gainlink_image PRIVATE "${GL_PORT_DIR}")
# The same MAVLink and CAN node libraries as the host apps (apps/mavlink, apps/can): no copy of protocol logic.
target_link_libraries(gainlink_image PRIVATE gainlink_mavlink_node gainlink_can_node gainlink_loop gainlink_gains m)
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

# Cortex-M image of a scheduled artifact (included from cmake/scheduled.cmake): the scheduled loop fed through
# semihosting files (main_sched.c). Boards as in cortex-m.cmake; no bus node on the UART.
set(GL_BOARDS_cortex-m0 microbit)
set(GL_BOARDS_cortex-m3 mps2-an385)
set(GL_BOARDS_cortex-m4 mps2-an386 netduinoplus2)
set(GL_BOARDS_cortex-m7 mps2-an500)
set(GL_BOARDS_cortex-m33 mps2-an505)
set(GL_BOARDS_cortex-m55 mps3-an547)
list(GET GL_BOARDS_${GL_TARGET} 0 GL_DEFAULT_BOARD)
set(GL_BOARD "${GL_DEFAULT_BOARD}" CACHE STRING "QEMU board of the image (${GL_BOARDS_${GL_TARGET}})")
if(NOT GL_BOARD IN_LIST GL_BOARDS_${GL_TARGET})
  message(FATAL_ERROR "GL_BOARD ${GL_BOARD} does not carry a ${GL_TARGET} (${GL_TARGET} boards: "
                      "${GL_BOARDS_${GL_TARGET}})")
endif()
if(GL_BOARD STREQUAL "microbit")
  set(GL_IMAGE_MAX_BLOCK 8)
else()
  set(GL_IMAGE_MAX_BLOCK 64)
endif()

set(GL_PORT_DIR "${CMAKE_CURRENT_SOURCE_DIR}/ports/cortex-m")
string(REPLACE "-" "_" GL_BOARD_STEM "${GL_BOARD}")
set(GL_LINKER_SCRIPT "${GL_PORT_DIR}/${GL_BOARD}.ld")
set(GL_IMAGE_SOURCES startup.c semihost.c main_sched.c gl_clock.c gl_uart.c no_heap.c "board_${GL_BOARD_STEM}.c")
if(GL_BOARD MATCHES "^mps")
  list(APPEND GL_IMAGE_SOURCES gl_cmsdk_uart.c)
endif()
list(TRANSFORM GL_IMAGE_SOURCES PREPEND "${GL_PORT_DIR}/")

add_executable(gainlink_image ${GL_IMAGE_SOURCES})
set_target_properties(gainlink_image PROPERTIES OUTPUT_NAME "gainlink_image" SUFFIX ".elf")
target_include_directories(gainlink_image PRIVATE "${GL_PORT_DIR}")
target_compile_definitions(gainlink_image PRIVATE GL_IMAGE_MAX_BLOCK=${GL_IMAGE_MAX_BLOCK})
target_link_libraries(gainlink_image PRIVATE gainlink_sched m)
target_link_options(gainlink_image PRIVATE "-L${GL_PORT_DIR}" "-T${GL_LINKER_SCRIPT}"
                    "-Wl,-Map=${CMAKE_CURRENT_BINARY_DIR}/gainlink_image.map")
set_target_properties(gainlink_image PROPERTIES LINK_DEPENDS "${GL_LINKER_SCRIPT}")
add_custom_command(TARGET gainlink_image POST_BUILD
  COMMAND "${CMAKE_OBJCOPY}" -O binary "$<TARGET_FILE:gainlink_image>" "${CMAKE_CURRENT_BINARY_DIR}/gainlink_image.bin"
  COMMAND "${CMAKE_OBJCOPY}" -O ihex "$<TARGET_FILE:gainlink_image>" "${CMAKE_CURRENT_BINARY_DIR}/gainlink_image.hex"
  VERBATIM)

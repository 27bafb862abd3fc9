# The QEMU board of a Cortex-M image and how an image is linked for it (included from cortex-m.cmake).
#
# Boards, one QEMU machine each (board file, linker script <board>.ld, the core it carries):
#   microbit       board_microbit.c     cortex-m0   nRF51822, 16 KiB RAM: on the UART the slcan node of an integer
#                                                law only
#   mps2-an385     board_mps2_an385.c   cortex-m3
#   mps2-an386     board_mps2_an386.c   cortex-m4   (default for cortex-m4)
#   netduinoplus2  board_netduinoplus2.c cortex-m4  STM32F405
#   mps2-an500     board_mps2_an500.c   cortex-m7
#   mps2-an505     board_mps2_an505.c   cortex-m33  Secure image, IoT Kit
#   mps3-an547     board_mps3_an547.c   cortex-m55  Secure image, SSE-300
# The micro:bit reads the replay stream 8 records at a time instead of 64 (GL_IMAGE_MAX_BLOCK).
include_guard(GLOBAL)
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
if(GL_BOARD STREQUAL "microbit")
  set(GL_IMAGE_MAX_BLOCK 8)
else()
  set(GL_IMAGE_MAX_BLOCK 64)
endif()

set(GL_PORT_DIR "${CMAKE_CURRENT_SOURCE_DIR}/ports/cortex-m")
string(REPLACE "-" "_" GL_BOARD_STEM "${GL_BOARD}")
set(GL_LINKER_SCRIPT "${GL_PORT_DIR}/${GL_BOARD}.ld")
set(GL_BOARD_SOURCES "board_${GL_BOARD_STEM}.c")
if(GL_BOARD MATCHES "^mps")
  list(APPEND GL_BOARD_SOURCES gl_cmsdk_uart.c)
endif()

# gl_add_image(NAME SOURCES <port sources...> LIBS <libraries...>): NAME.elf (and .bin, .hex, .map) for GL_BOARD from
# the start-up, semihosting, clock, UART and heap-guard sources of the port, the board's files and SOURCES.
function(gl_add_image name)
  cmake_parse_arguments(IMG "" "" "SOURCES;LIBS" ${ARGN})
  set(sources startup.c semihost.c gl_clock.c gl_uart.c no_heap.c ${IMG_SOURCES} ${GL_BOARD_SOURCES})
  list(TRANSFORM sources PREPEND "${GL_PORT_DIR}/")
  add_executable(${name} ${sources})
  set_target_properties(${name} PROPERTIES OUTPUT_NAME "${name}" SUFFIX ".elf" LINK_DEPENDS "${GL_LINKER_SCRIPT}")
  target_include_directories(${name} PRIVATE "${GL_PORT_DIR}")
  target_compile_definitions(${name} PRIVATE GL_IMAGE_MAX_BLOCK=${GL_IMAGE_MAX_BLOCK})
  if(GL_SKIP_FPU_ENABLE)
    target_compile_definitions(${name} PRIVATE GL_SKIP_FPU_ENABLE=1)
  endif()
  target_link_libraries(${name} PRIVATE ${IMG_LIBS})
  target_link_options(${name} PRIVATE "-L${GL_PORT_DIR}" "-T${GL_LINKER_SCRIPT}"
                      "-Wl,-Map=${CMAKE_CURRENT_BINARY_DIR}/${name}.map")
  add_custom_command(TARGET ${name} POST_BUILD
    COMMAND "${CMAKE_OBJCOPY}" -O binary "$<TARGET_FILE:${name}>" "${CMAKE_CURRENT_BINARY_DIR}/${name}.bin"
    COMMAND "${CMAKE_OBJCOPY}" -O ihex "$<TARGET_FILE:${name}>" "${CMAKE_CURRENT_BINARY_DIR}/${name}.hex"
    VERBATIM)
endfunction()

# The fixed-point loop (included from firmware/CMakeLists.txt when GL_GAINS_DIR holds gl_fixed_gains.c, i.e. the
# artifact is a fixed-point design: `[implementation] numeric = "q31" | "q15"`).
#   gainlink_fixed         static library: src/gl_fixed.c and the generated gl_fixed_gains_default
#   host:      gainlink_fixed_host (shared, for Python ctypes: gainlink.firmware.fixed), gainlink_fixed_loop_host
#              (executable, text in and out: the ASan/UBSan runs)
#   cortex-m*: gainlink_fixed_image (.elf/.bin/.hex/.map): replay over semihosting (ports/cortex-m/main_fixed.c)
# The float32 targets are built beside them from the same export, unchanged.
add_library(gainlink_fixed STATIC src/gl_fixed.c "${GL_GAINS_DIR}/gl_fixed_gains.c")
target_link_libraries(gainlink_fixed PUBLIC gainlink_config)
target_include_directories(gainlink_fixed PUBLIC "${CMAKE_CURRENT_SOURCE_DIR}/src")
target_compile_options(gainlink_fixed PRIVATE -Wvla -Wshadow -Wstrict-prototypes)
option(GL_FIXED_UNROLLED "Fixed point: the generated row sums (gl_fixed_step.h) instead of the generic loop" ON)
if(GL_FIXED_UNROLLED)
  target_compile_definitions(gainlink_fixed PRIVATE GL_FX_UNROLLED=1)
endif()

if(GL_TARGET STREQUAL "host")
  add_library(gainlink_fixed_host SHARED ports/host/gl_fixed_host.c)
  target_link_libraries(gainlink_fixed_host PRIVATE gainlink_fixed)
  target_link_options(gainlink_fixed_host PRIVATE -Wl,--no-undefined)
  add_executable(gainlink_fixed_loop_host ports/host/fixed_main.c) # text in and out (runs under GL_SANITIZE)
  target_link_libraries(gainlink_fixed_loop_host PRIVATE gainlink_fixed)
elseif(GL_TARGET IN_LIST GL_CORTEX_M_TARGETS)
  set(GL_FIXED_IMAGE_SOURCES startup.c semihost.c main_fixed.c gl_stream.c gl_clock.c gl_uart.c no_heap.c)
  if(GL_BOARD MATCHES "^mps")
    list(APPEND GL_FIXED_IMAGE_SOURCES gl_cmsdk_uart.c)
  endif()
  list(TRANSFORM GL_FIXED_IMAGE_SOURCES PREPEND "${GL_PORT_DIR}/")
  add_executable(gainlink_fixed_image ${GL_FIXED_IMAGE_SOURCES} "${GL_BOARD_SRC}")
  set_target_properties(gainlink_fixed_image PROPERTIES OUTPUT_NAME "gainlink_fixed_image" SUFFIX ".elf")
  target_include_directories(gainlink_fixed_image PRIVATE "${GL_PORT_DIR}")
  target_compile_definitions(gainlink_fixed_image PRIVATE GL_IMAGE_MAX_BLOCK=${GL_IMAGE_MAX_BLOCK})
  target_link_libraries(gainlink_fixed_image PRIVATE gainlink_fixed)
  if(GL_SKIP_FPU_ENABLE)
    target_compile_definitions(gainlink_fixed_image PRIVATE GL_SKIP_FPU_ENABLE=1)
  endif()
  target_link_options(gainlink_fixed_image PRIVATE "-L${GL_PORT_DIR}" "-T${GL_LINKER_SCRIPT}"
                      "-Wl,-Map=${CMAKE_CURRENT_BINARY_DIR}/gainlink_fixed_image.map")
  set_target_properties(gainlink_fixed_image PROPERTIES LINK_DEPENDS "${GL_LINKER_SCRIPT}")
  add_custom_command(TARGET gainlink_fixed_image POST_BUILD
    COMMAND "${CMAKE_OBJCOPY}" -O binary "$<TARGET_FILE:gainlink_fixed_image>"
            "${CMAKE_CURRENT_BINARY_DIR}/gainlink_fixed_image.bin"
    COMMAND "${CMAKE_OBJCOPY}" -O ihex "$<TARGET_FILE:gainlink_fixed_image>"
            "${CMAKE_CURRENT_BINARY_DIR}/gainlink_fixed_image.hex"
    VERBATIM)
endif()

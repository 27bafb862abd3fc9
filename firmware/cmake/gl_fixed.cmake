# The fixed-point loop (included from firmware/CMakeLists.txt when GL_GAINS_DIR holds gl_fixed_gains.c, i.e. the
# artifact is a fixed-point design: `[implementation] numeric = "q31" | "q15"`).
#   gainlink_fixed         static library: src/gl_fixed.c and the generated gl_fixed_gains_default, with the
#                          generated row sums (GL_FIXED_UNROLLED)
#   gainlink_fixed_generic static library: the same sources with the generic loop, its gains all data (the
#                          MAVLink node's, whose uploaded set may carry other shifts; bit for bit the unrolled one)
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
add_library(gainlink_fixed_generic STATIC src/gl_fixed.c "${GL_GAINS_DIR}/gl_fixed_gains.c")
target_link_libraries(gainlink_fixed_generic PUBLIC gainlink_config)
target_include_directories(gainlink_fixed_generic PUBLIC "${CMAKE_CURRENT_SOURCE_DIR}/src")
target_compile_options(gainlink_fixed_generic PRIVATE -Wvla -Wshadow -Wstrict-prototypes)

if(GL_TARGET STREQUAL "host")
  add_library(gainlink_fixed_host SHARED ports/host/gl_fixed_host.c)
  target_link_libraries(gainlink_fixed_host PRIVATE gainlink_fixed)
  target_link_options(gainlink_fixed_host PRIVATE -Wl,--no-undefined)
  add_executable(gainlink_fixed_loop_host ports/host/fixed_main.c) # text in and out (runs under GL_SANITIZE)
  target_link_libraries(gainlink_fixed_loop_host PRIVATE gainlink_fixed)
elseif(GL_TARGET IN_LIST GL_CORTEX_M_TARGETS)
  gl_add_image(gainlink_fixed_image SOURCES main_fixed.c gl_stream.c LIBS gainlink_fixed) # board-image.cmake
endif()

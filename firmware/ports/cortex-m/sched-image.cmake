# Cortex-M image of a scheduled artifact (included from cmake/scheduled.cmake): the scheduled loop fed through
# semihosting files (main_sched.c). Boards and linking: board-image.cmake; no bus node on the UART.
include("${CMAKE_CURRENT_LIST_DIR}/board-image.cmake")
gl_add_image(gainlink_image SOURCES main_sched.c LIBS gainlink_sched m)

# The law the build runs (firmware/include/gainlink/gl_law.h): the export's, named in its gl_gains.h
# (`#define GL_LAW_STRUCTURE lq|scheduled|mpc`, `#define GL_LAW_NUMERIC float32|q31|q15`), unless GL_LAW names another
# that the export also holds (a benchmark baseline: the float32 loop of a q31 artifact, GL_LAW=lq_float32).
#
# Sets GL_LAW_EXPORTED (the export's law) and GL_LAW_BUILT (the one built), and defines gl_add_law(NAME VARIANT
# unrolled|generic): the law's static library, its sources below (the law's own in src/ and the export's generated
# gains), with GL_LAW=<law> PUBLIC so that every main and node linking it compiles the same law. A law has at most
# two variants: the unrolled one (the generated step: GL_STEP_UNROLLED for lq_float32, GL_FIXED_UNROLLED's row sums
# for the integer laws; the options turn them off for a baseline) and, for the integer laws, the generic one that
# reads every shift and signal from its set (an uploaded set may carry other shifts: the MAVLink node's).
include_guard(GLOBAL)

set(GL_LAW "" CACHE STRING "Build this law instead of the export's (lq_float32, lq_q31, lq_q15, scheduled_float32, mpc_float32)")
option(GL_STEP_UNROLLED "lq_float32: the generated, fully unrolled step (gl_step.h) instead of the generic loops" ON)
option(GL_FIXED_UNROLLED "Integer laws: the generated row sums (gl_fixed_step.h) instead of the generic loop" ON)

if(NOT GL_GAINS_DIR OR NOT EXISTS "${GL_GAINS_DIR}/gl_gains.h")
  message(FATAL_ERROR "GL_GAINS_DIR must name a directory written by `gainlink export` (got '${GL_GAINS_DIR}')")
endif()
file(STRINGS "${GL_GAINS_DIR}/gl_gains.h" _gl_structure REGEX "^#define GL_LAW_STRUCTURE [a-z]+")
file(STRINGS "${GL_GAINS_DIR}/gl_gains.h" _gl_numeric REGEX "^#define GL_LAW_NUMERIC [a-z0-9]+")
if(NOT _gl_structure OR NOT _gl_numeric)
  message(FATAL_ERROR "${GL_GAINS_DIR}/gl_gains.h names no law (GL_LAW_STRUCTURE, GL_LAW_NUMERIC): export it again")
endif()
string(REGEX REPLACE "^#define GL_LAW_STRUCTURE ([a-z]+).*" "\\1" _gl_structure "${_gl_structure}")
string(REGEX REPLACE "^#define GL_LAW_NUMERIC ([a-z0-9]+).*" "\\1" _gl_numeric "${_gl_numeric}")
set(GL_LAW_EXPORTED "${_gl_structure}_${_gl_numeric}")
if(GL_LAW)
  set(GL_LAW_BUILT "${GL_LAW}")
else()
  set(GL_LAW_BUILT "${GL_LAW_EXPORTED}")
endif()
# The nodes' parameter tables are the export's law's (gl_law_params.h): a build of another law (a baseline) runs the
# law alone, over replay and PIL, without the bus nodes.
if(GL_LAW_BUILT STREQUAL GL_LAW_EXPORTED)
  set(GL_LAW_NODES ON)
else()
  set(GL_LAW_NODES OFF)
endif()

# Each law: its sources (@GAINS@: the export's folder), and the macro of its unrolled variant and the option of it.
set(GL_LAW_SOURCES_lq_float32 src/gl_loop.c src/gl_gains_check.c src/gl_fmaf.c @GAINS@/gl_gains.c)
set(GL_LAW_UNROLLED_lq_float32 GL_STEP_UNROLLED)
set(GL_LAW_SOURCES_lq_q31 src/gl_fixed.c @GAINS@/gl_fixed_gains.c)
set(GL_LAW_UNROLLED_lq_q31 GL_FX_UNROLLED)
set(GL_LAW_SOURCES_lq_q15 ${GL_LAW_SOURCES_lq_q31})
set(GL_LAW_UNROLLED_lq_q15 GL_FX_UNROLLED)
set(GL_LAW_SOURCES_scheduled_float32 src/gl_sched.c src/gl_fmaf.c @GAINS@/gl_sched_gains.c)
set(GL_LAW_UNROLLED_scheduled_float32 "")
set(GL_LAW_SOURCES_mpc_float32 src/gl_mpc.c src/gl_fmaf.c @GAINS@/gl_mpc_gains.c)
set(GL_LAW_UNROLLED_mpc_float32 "")
set(_gl_option_GL_STEP_UNROLLED ${GL_STEP_UNROLLED})
set(_gl_option_GL_FX_UNROLLED ${GL_FIXED_UNROLLED})

if(NOT DEFINED GL_LAW_SOURCES_${GL_LAW_BUILT})
  message(FATAL_ERROR "GL_LAW must be lq_float32, lq_q31, lq_q15, scheduled_float32 or mpc_float32 (got '${GL_LAW_BUILT}')")
endif()
set(GL_LAW_SOURCES "")
foreach(_gl_source IN LISTS GL_LAW_SOURCES_${GL_LAW_BUILT})
  string(REPLACE "@GAINS@" "${GL_GAINS_DIR}" _gl_source "${_gl_source}")
  if(_gl_source MATCHES "^${GL_GAINS_DIR}" AND NOT EXISTS "${_gl_source}")
    get_filename_component(_gl_name "${_gl_source}" NAME)
    message(FATAL_ERROR "GL_LAW ${GL_LAW_BUILT}: the export of a ${GL_LAW_EXPORTED} artifact holds no ${_gl_name}")
  endif()
  list(APPEND GL_LAW_SOURCES "${_gl_source}")
endforeach()
set(GL_LAW_UNROLLED_MACRO "${GL_LAW_UNROLLED_${GL_LAW_BUILT}}")
# The integer laws' generic variant is a library of its own; the others have one variant for every consumer.
# GL_LAW_INTEGER: an integer law (what a core without an FPU runs: the micro:bit's image carries its slcan node).
if(GL_LAW_UNROLLED_MACRO STREQUAL "GL_FX_UNROLLED")
  set(GL_LAW_HAS_GENERIC ON)
  set(GL_LAW_INTEGER ON)
else()
  set(GL_LAW_HAS_GENERIC OFF)
  set(GL_LAW_INTEGER OFF)
endif()

# gl_add_law(NAME VARIANT unrolled|generic): the law's static library NAME.
function(gl_add_law name)
  cmake_parse_arguments(LAW "" "VARIANT" "" ${ARGN})
  add_library(${name} STATIC ${GL_LAW_SOURCES})
  target_link_libraries(${name} PUBLIC gainlink_config)
  target_include_directories(${name} PRIVATE "${CMAKE_CURRENT_SOURCE_DIR}/src")
  target_compile_options(${name} PRIVATE -Wvla -Wshadow -Wstrict-prototypes) # no VLAs in the library
  target_compile_definitions(${name} PUBLIC GL_LAW=${GL_LAW_BUILT})
  if(LAW_VARIANT STREQUAL "unrolled" AND GL_LAW_UNROLLED_MACRO AND _gl_option_${GL_LAW_UNROLLED_MACRO})
    target_compile_definitions(${name} PUBLIC ${GL_LAW_UNROLLED_MACRO}=1)
  endif()
  target_link_libraries(${name} PUBLIC m)
  if(NOT GL_TARGET IN_LIST GL_CORTEX_M_TARGETS)
    return()
  elseif(GL_SOFT_FMA STREQUAL "newlib")
    target_compile_definitions(${name} PRIVATE GL_SOFT_FMA_NEWLIB=1)
  elseif(GL_SOFT_FMA STREQUAL "plain")
    target_compile_definitions(${name} PRIVATE GL_SOFT_FMA_PLAIN=1)
  elseif(NOT GL_SOFT_FMA STREQUAL "exact")
    message(FATAL_ERROR "GL_SOFT_FMA must be exact, newlib or plain (got '${GL_SOFT_FMA}')")
  endif()
endfunction()

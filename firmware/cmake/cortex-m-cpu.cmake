# Compiler flags per Cortex-M target (GL_TARGET): core, FPU and float ABI, always Thumb. Included by the
# arm-none-eabi toolchain file (initial flags, also seen by CMake's compiler checks) and by CMakeLists.txt
# (on gainlink_config, so a user's CMAKE_C_FLAGS cannot drop them). Sets GL_CPU_FLAGS (a list).
#   cortex-m0   ARMv6-M, no FPU: soft float (newlib/libgcc routines; multiply-adds through gl_fmaf.c)
#   cortex-m3   ARMv7-M, no FPU: soft float
#   cortex-m4   ARMv7E-M, single-precision FPv4 (vfma.f32)
#   cortex-m7   ARMv7E-M, double-precision FPv5 (the MPS2 AN500 image and QEMU's model have the DP FPU)
#   cortex-m33  ARMv8-M Mainline, single-precision FPv5
#   cortex-m55  ARMv8.1-M, FPv5 with double precision and half precision, Helium (MVE integer and float):
#               -mfpu=auto takes all of it from -mcpu
set(GL_CORTEX_M_TARGETS cortex-m0 cortex-m3 cortex-m4 cortex-m7 cortex-m33 cortex-m55)

if(GL_TARGET STREQUAL "cortex-m0")
  set(GL_CPU_FLAGS -mcpu=cortex-m0 -mfloat-abi=soft)
elseif(GL_TARGET STREQUAL "cortex-m3")
  set(GL_CPU_FLAGS -mcpu=cortex-m3 -mfloat-abi=soft)
elseif(GL_TARGET STREQUAL "cortex-m4")
  set(GL_CPU_FLAGS -mcpu=cortex-m4 -mfpu=fpv4-sp-d16 -mfloat-abi=hard)
elseif(GL_TARGET STREQUAL "cortex-m7")
  set(GL_CPU_FLAGS -mcpu=cortex-m7 -mfpu=fpv5-d16 -mfloat-abi=hard)
elseif(GL_TARGET STREQUAL "cortex-m33")
  set(GL_CPU_FLAGS -mcpu=cortex-m33 -mfpu=fpv5-sp-d16 -mfloat-abi=hard)
elseif(GL_TARGET STREQUAL "cortex-m55")
  set(GL_CPU_FLAGS -mcpu=cortex-m55 -mfpu=auto -mfloat-abi=hard)
else()
  message(FATAL_ERROR "GL_TARGET must be one of ${GL_CORTEX_M_TARGETS} for the arm-none-eabi toolchain "
                      "(got '${GL_TARGET}')")
endif()
list(APPEND GL_CPU_FLAGS -mthumb)

# CMake toolchain file: GNU Arm Embedded (arm-none-eabi) for a Cortex-M target. Pass -DGL_TARGET=cortex-mN
# (cortex-m4 when absent); the core, FPU and float-ABI flags come from cortex-m-cpu.cmake.
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES GL_TARGET)

if(NOT GL_TARGET)
  set(GL_TARGET cortex-m4)
endif()
include("${CMAKE_CURRENT_LIST_DIR}/cortex-m-cpu.cmake")
string(JOIN " " GL_CPU_FLAGS_STRING ${GL_CPU_FLAGS})

find_program(GL_ARM_GCC arm-none-eabi-gcc REQUIRED)
get_filename_component(GL_ARM_BIN "${GL_ARM_GCC}" DIRECTORY)
set(CMAKE_C_COMPILER "${GL_ARM_GCC}")
set(CMAKE_ASM_COMPILER "${GL_ARM_GCC}")
set(CMAKE_OBJCOPY "${GL_ARM_BIN}/arm-none-eabi-objcopy" CACHE FILEPATH "objcopy")
set(CMAKE_SIZE "${GL_ARM_BIN}/arm-none-eabi-size" CACHE FILEPATH "size")

set(CMAKE_C_FLAGS_INIT "${GL_CPU_FLAGS_STRING} -ffunction-sections -fdata-sections")
set(CMAKE_EXE_LINKER_FLAGS_INIT "${GL_CPU_FLAGS_STRING} -nostartfiles --specs=nano.specs -Wl,--gc-sections")

set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)

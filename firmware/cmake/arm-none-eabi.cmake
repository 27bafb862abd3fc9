# CMake toolchain file: GNU Arm Embedded (arm-none-eabi) for the Cortex-M4F with the single-precision FPU.
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)

find_program(GL_ARM_GCC arm-none-eabi-gcc REQUIRED)
get_filename_component(GL_ARM_BIN "${GL_ARM_GCC}" DIRECTORY)
set(CMAKE_C_COMPILER "${GL_ARM_GCC}")
set(CMAKE_ASM_COMPILER "${GL_ARM_GCC}")
set(CMAKE_OBJCOPY "${GL_ARM_BIN}/arm-none-eabi-objcopy" CACHE FILEPATH "objcopy")
set(CMAKE_SIZE "${GL_ARM_BIN}/arm-none-eabi-size" CACHE FILEPATH "size")

set(GL_CPU_FLAGS "-mcpu=cortex-m4 -mfpu=fpv4-sp-d16 -mfloat-abi=hard -mthumb")
set(CMAKE_C_FLAGS_INIT "${GL_CPU_FLAGS} -ffunction-sections -fdata-sections")
set(CMAKE_EXE_LINKER_FLAGS_INIT "${GL_CPU_FLAGS} -nostartfiles --specs=nano.specs -Wl,--gc-sections")

set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)

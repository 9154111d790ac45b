# Cross toolchain: Cortex-M4F (single-precision FPU, hard-float ABI), bare metal,
# Debian's gcc-arm-none-eabi + libnewlib-arm-none-eabi.
#
#   cmake -S . -B build/target -DCMAKE_TOOLCHAIN_FILE=firmware/toolchain/arm-none-eabi-cortex-m4f.cmake
#
# Executables are ELFs for QEMU's mps2-an386 board (Cortex-M4 + FPU); ctest runs
# them through CMAKE_CROSSCOMPILING_EMULATOR below.
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)

find_program(PROPID_ARM_GCC arm-none-eabi-gcc REQUIRED)
set(CMAKE_C_COMPILER "${PROPID_ARM_GCC}")
set(CMAKE_ASM_COMPILER "${PROPID_ARM_GCC}")
get_filename_component(_propid_arm_bin "${PROPID_ARM_GCC}" DIRECTORY)
set(CMAKE_AR "${_propid_arm_bin}/arm-none-eabi-ar" CACHE FILEPATH "")
set(CMAKE_RANLIB "${_propid_arm_bin}/arm-none-eabi-ranlib" CACHE FILEPATH "")
set(CMAKE_NM "${_propid_arm_bin}/arm-none-eabi-nm" CACHE FILEPATH "")
set(CMAKE_OBJDUMP "${_propid_arm_bin}/arm-none-eabi-objdump" CACHE FILEPATH "")
set(CMAKE_SIZE "${_propid_arm_bin}/arm-none-eabi-size" CACHE FILEPATH "")

# The compiler checks cannot link a bare-metal program without our startup code.
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)

set(PROPID_CPU_FLAGS "-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard")
# -fno-math-errno lets sqrtf become the vsqrt.f32 instruction.
# -ffp-contract=fast: with -std=c11 GCC would otherwise not fuse a*b+c into vfma.
# -fstack-usage writes a .su file per object (make target reports the worst frame),
# -fcallgraph-info=su a .ci call graph with frame sizes (worst call chains, recursion).
set(CMAKE_C_FLAGS_INIT
    "${PROPID_CPU_FLAGS} -fno-math-errno -ffp-contract=fast -fstack-usage -fcallgraph-info=su -ffunction-sections -fdata-sections")
set(CMAKE_ASM_FLAGS_INIT "${PROPID_CPU_FLAGS}")
# CMake's GNU module appends -O3 to *_INIT values, so pin the per-config flags in
# the cache (FORCE: an existing build directory picks up a change here too).
set(CMAKE_C_FLAGS_RELEASE "-O2 -DNDEBUG" CACHE STRING "Cortex-M4F release flags" FORCE)
set(CMAKE_C_FLAGS_DEBUG "-Og -g" CACHE STRING "Cortex-M4F debug flags" FORCE)
set(CMAKE_EXE_LINKER_FLAGS_INIT "${PROPID_CPU_FLAGS} -Wl,--gc-sections")

set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)

# ctest prepends this to every test command; the ELF path comes last (after -kernel).
# Semihosting carries the program's output to QEMU's stdout and its exit status
# to QEMU's exit code.
find_program(PROPID_QEMU_ARM qemu-system-arm)
if(PROPID_QEMU_ARM)
  set(CMAKE_CROSSCOMPILING_EMULATOR
      "${PROPID_QEMU_ARM};-M;mps2-an386;-nographic;-monitor;none;-serial;none;-semihosting-config;enable=on,target=native;-kernel")
endif()

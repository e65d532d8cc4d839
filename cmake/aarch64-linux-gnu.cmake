# Cross build for arm64 boards with Debian's cross toolchain (crossbuild-essential-arm64) and multiarch
# libraries (libopencv-dev:arm64 and the rest, installed beside the build machine's tools).
#   cmake -S . -B build-arm64 -G Ninja -DCMAKE_TOOLCHAIN_FILE=cmake/aarch64-linux-gnu.cmake
# scripts/cross-arm64.sh does all of it in a throwaway bookworm root and runs the unit tests under qemu-user.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)
# Programs (idlc, the Cyclone DDS IDL compiler) are the build machine's; libraries and headers the target's.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(ENV{PKG_CONFIG_LIBDIR} "/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig")
# gtest_discover_tests and ctest run the arm64 test binaries through qemu-user.
find_program(STEREOD_QEMU_AARCH64 qemu-aarch64 qemu-aarch64-static)
if(STEREOD_QEMU_AARCH64)
  set(CMAKE_CROSSCOMPILING_EMULATOR "${STEREOD_QEMU_AARCH64}")
endif()
# The package's architecture is the target's, not the build machine's (what dpkg --print-architecture says).
set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE arm64)

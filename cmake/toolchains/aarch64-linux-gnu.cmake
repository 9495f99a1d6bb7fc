# SPDX-License-Identifier: MIT
# Cross build for an arm64 (aarch64) Debian 12 board: Debian's cross compilers
# (crossbuild-essential-arm64) against a sysroot of Debian 12's arm64 packages, and qemu-user to
# run the tests. tools/setup.sh --arm64 installs the compilers and qemu and makes the sysroot
# (build/arm64-sysroot: the -dev packages of tools/arm64-sysroot-packages.txt, unpacked, so that
# the build machine's own amd64 -dev packages stay as they are; Debian's liblcm-dev and
# libode-dev cannot be installed for two architectures at once). Preset: robot-arm64.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)

get_filename_component(_b21r_root "${CMAKE_CURRENT_LIST_DIR}/../.." ABSOLUTE)
set(B21R_ARM64_SYSROOT "${_b21r_root}/build/arm64-sysroot")
if(NOT EXISTS "${B21R_ARM64_SYSROOT}/usr/include/lcm/lcm.h")
  message(FATAL_ERROR "b21r: no arm64 sysroot at ${B21R_ARM64_SYSROOT}: run tools/setup.sh --arm64")
endif()
set(CMAKE_SYSROOT "${B21R_ARM64_SYSROOT}")
# Programs (lcm-gen, javac, Python) are the build machine's; libraries, headers and CMake
# packages the target's.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
set(ENV{PKG_CONFIG_SYSROOT_DIR} "${B21R_ARM64_SYSROOT}")
set(ENV{PKG_CONFIG_LIBDIR}
  "${B21R_ARM64_SYSROOT}/usr/lib/aarch64-linux-gnu/pkgconfig:${B21R_ARM64_SYSROOT}/usr/share/pkgconfig")
# CTest runs every test program under qemu-user with the sysroot's libraries (the loader
# /lib/ld-linux-aarch64.so.1 and the shared libraries come from there).
set(CMAKE_CROSSCOMPILING_EMULATOR qemu-aarch64 -L "${B21R_ARM64_SYSROOT}")

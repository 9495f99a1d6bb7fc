# SPDX-License-Identifier: MIT
# Every third-party dependency is found here and exposed as an imported target, so the rest of
# the build links names (Eigen3::Eigen, PkgConfig::ODE, b21r::lcm, b21r::cmocka, ...) only.
# All come from Debian 12 packages; tools/setup.sh installs them (list: tools/debian-packages.txt).
include(FindPackageHandleStandardArgs)
find_package(PkgConfig REQUIRED)

# Eigen (header-only) for HEDGER's local regressions.
find_package(Eigen3 3.4 REQUIRED CONFIG)

# LCM: Debian ships a pkg-config file that pulls in GLib, and no CMake config. Find the header
# and the library directly so that the C libraries need nothing else.
find_path(LCM_INCLUDE_DIR lcm/lcm.h)
find_library(LCM_LIBRARY NAMES lcm)
find_program(LCM_GEN_EXECUTABLE lcm-gen)
find_package_handle_standard_args(LCM REQUIRED_VARS LCM_LIBRARY LCM_INCLUDE_DIR LCM_GEN_EXECUTABLE)
if(NOT TARGET b21r::lcm)
  add_library(b21r::lcm UNKNOWN IMPORTED)
  set_target_properties(b21r::lcm PROPERTIES
    IMPORTED_LOCATION "${LCM_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${LCM_INCLUDE_DIR}")
endif()
# The jar is the build machine's (Java is the same on every architecture), also in a cross build.
find_file(LCM_JAR lcm.jar PATHS /usr/share/java /usr/local/share/java NO_CMAKE_FIND_ROOT_PATH)

# ODE (double precision in Debian) and libccd: pkg-config only.
if(B21R_BUILD_SIM)
  pkg_check_modules(ODE REQUIRED IMPORTED_TARGET ode)
  pkg_check_modules(CCD REQUIRED IMPORTED_TARGET ccd)
endif()

if(BUILD_TESTING)
  # CMocka's Debian config sets variables only: wrap them in one target.
  find_package(cmocka 1.1 REQUIRED CONFIG)
  if(NOT TARGET b21r::cmocka)
    add_library(b21r::cmocka UNKNOWN IMPORTED)
    set_target_properties(b21r::cmocka PROPERTIES
      IMPORTED_LOCATION "${CMOCKA_LIBRARY}"
      INTERFACE_INCLUDE_DIRECTORIES "${CMOCKA_INCLUDE_DIR}")
  endif()
endif()

if(B21R_BUILD_BENCHMARKS)
  find_package(benchmark REQUIRED CONFIG)
  # nanoflann is the reference k-d tree in the HEDGER benchmark only (header-only).
  find_path(NANOFLANN_INCLUDE_DIR nanoflann.hpp REQUIRED)
  if(NOT TARGET b21r::nanoflann)
    add_library(b21r::nanoflann INTERFACE IMPORTED)
    set_target_properties(b21r::nanoflann PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${NANOFLANN_INCLUDE_DIR}")
  endif()
  # valgrind's callgrind counts the instructions of the benchmarks' budgets (test/bench/support).
  find_program(VALGRIND_EXECUTABLE valgrind REQUIRED)
  find_path(VALGRIND_INCLUDE_DIR valgrind/callgrind.h REQUIRED)
endif()

find_package(Threads REQUIRED)

# OpenSSL's libcrypto: HMAC-SHA256, SHA-256 and the CSPRNG of the authenticated operator messages
# (firmware/core/src/opauth.c). Debian's libssl-dev; FindOpenSSL gives OpenSSL::Crypto.
if(B21R_BUILD_FIRMWARE)
  find_package(OpenSSL 3 REQUIRED COMPONENTS Crypto)
endif()

if(B21R_BUILD_JAVA_TYPES)
  find_package(Java 11 COMPONENTS Development)
  if(NOT Java_FOUND OR NOT LCM_JAR)
    message(STATUS "b21r: no JDK or lcm.jar: the lcm-spy type jar will not be built")
  endif()
endif()

find_package(Python3 3.9 COMPONENTS Interpreter REQUIRED)

# Debian's lcm-gen 1.3.1 writes Python that fails on boolean arrays under Python 3
# ("'map' object is not subscriptable"); the lcm wheel pinned in tools/requirements.txt ships a
# fixed lcm-gen next to the interpreter. C and Java still come from Debian's lcm-gen so that they
# match Debian's liblcm; the round-trip tests prove all three agree byte for byte.
get_filename_component(_b21r_python_bin "${Python3_EXECUTABLE}" DIRECTORY)
find_program(LCM_GEN_PYTHON_EXECUTABLE lcm-gen PATHS "${_b21r_python_bin}" NO_DEFAULT_PATH)
if(NOT LCM_GEN_PYTHON_EXECUTABLE)
  message(WARNING "b21r: no lcm-gen beside ${Python3_EXECUTABLE} (run tools/setup.sh); "
                  "using ${LCM_GEN_EXECUTABLE} for Python, whose boolean arrays fail on Python 3")
  set(LCM_GEN_PYTHON_EXECUTABLE "${LCM_GEN_EXECUTABLE}")
endif()

# SPDX-License-Identifier: MIT
# B21R_SANITIZE: semicolon list of sanitizers (e.g. "address;undefined") applied to every target
# of the project through the b21r_sanitizers INTERFACE target, which B21rWarnings users link too.
set(B21R_SANITIZE "" CACHE STRING "Sanitizers for the whole build, e.g. address;undefined")
add_library(b21r_sanitizers INTERFACE)
add_library(b21r::sanitizers ALIAS b21r_sanitizers)
if(B21R_SANITIZE)
  list(JOIN B21R_SANITIZE "," _b21r_san)
  target_compile_options(b21r_sanitizers INTERFACE
    -fsanitize=${_b21r_san} -fno-omit-frame-pointer -fno-sanitize-recover=all)
  target_link_options(b21r_sanitizers INTERFACE -fsanitize=${_b21r_san})
endif()
# Fuzz builds: every project target reports its coverage to libFuzzer (the fuzz targets link the
# runtime with -fsanitize=fuzzer), so the fuzzers are guided by the code under test, not only by
# their own harness.
if(B21R_BUILD_FUZZERS AND CMAKE_C_COMPILER_ID MATCHES "Clang")
  target_compile_options(b21r_sanitizers INTERFACE -fsanitize=fuzzer-no-link)
endif()
# Every project target gets warnings and sanitizers through this one link.
target_link_libraries(b21r_warnings INTERFACE b21r_sanitizers)

# SPDX-License-Identifier: MIT
# One home for the compiler warnings of the project's own code (never applied to dependencies
# or generated code). Link b21r_warnings PRIVATE to every target we write.
add_library(b21r_warnings INTERFACE)
add_library(b21r::warnings ALIAS b21r_warnings)
target_compile_options(b21r_warnings INTERFACE
  -Wall -Wextra -pedantic
  -Wconversion -Wsign-conversion -Wdouble-promotion -Wundef
  -Wcast-align -Wshadow -Wformat=2 -Wnull-dereference -Wmissing-declarations
  $<$<COMPILE_LANGUAGE:C>:-Wstrict-prototypes -Wmissing-prototypes>
  $<$<COMPILE_LANGUAGE:CXX>:-Wnon-virtual-dtor -Wold-style-cast -Woverloaded-virtual>
  # Tests compare results bit for bit on purpose (determinism, round trips): they set the target
  # property B21R_EXACT_FLOAT_COMPARE to drop -Wfloat-equal.
  $<$<NOT:$<BOOL:$<TARGET_PROPERTY:B21R_EXACT_FLOAT_COMPARE>>>:-Wfloat-equal>
  $<$<BOOL:${B21R_WERROR}>:-Werror>)

# SPDX-License-Identifier: MIT
# Test helpers. CTest names are <module>.<area>; labels are unit | integration | bench | fuzz.
#
# b21r_add_unit_test(<module>.<area> SOURCES <files>... [LIBS <targets>...] [LABELS <labels>...]
#                    [TIMEOUT <s>] [ARGS <args>...])
#   Builds executable test_<module>_<area> with CMocka, the allocation counter and the project
#   warnings, and registers it with CTest under label "unit" (plus LABELS).
function(b21r_add_unit_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;LIBS;LABELS;ARGS" ${ARGN})
  string(REPLACE "." "_" exe "test_${name}")
  add_executable(${exe} ${ARG_SOURCES})
  target_link_libraries(${exe} PRIVATE b21r::test_support b21r::cmocka b21r_warnings ${ARG_LIBS})
  # Tests compare floating-point results bit for bit on purpose (determinism, round trips).
  set_target_properties(${exe} PROPERTIES B21R_EXACT_FLOAT_COMPARE ON)
  add_test(NAME ${name} COMMAND ${exe} ${ARG_ARGS})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 120)
  endif()
  set_tests_properties(${name} PROPERTIES LABELS "unit;${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
    ENVIRONMENT "CMOCKA_MESSAGE_OUTPUT=STDOUT")
endfunction()

# b21r_add_integration_test(<module>.<area> COMMAND <cmd>... [LABELS ...] [TIMEOUT <s>])
#   Registers a command (script or executable) under label "integration".
function(b21r_add_integration_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT;WORKING_DIRECTORY" "COMMAND;LABELS;ENVIRONMENT" ${ARGN})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  if(NOT ARG_WORKING_DIRECTORY)
    set(ARG_WORKING_DIRECTORY "${CMAKE_CURRENT_BINARY_DIR}")
  endif()
  add_test(NAME ${name} COMMAND ${ARG_COMMAND} WORKING_DIRECTORY "${ARG_WORKING_DIRECTORY}")
  set_tests_properties(${name} PROPERTIES LABELS "integration;${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
    SKIP_RETURN_CODE 77)
  if(ARG_ENVIRONMENT)
    set_tests_properties(${name} PROPERTIES ENVIRONMENT "${ARG_ENVIRONMENT}")
  endif()
endfunction()

# b21r_add_python_test(<module>.<area> SCRIPT <file.py> [ARGS ...] [LABELS ...] [TIMEOUT <s>])
#   Runs a Python test script with the tools' virtual environment, the generated LCM types and
#   the project's Python packages on PYTHONPATH; in a sanitized build also with the sanitizer
#   runtime preloaded that the compiled b21r_learn module needs (B21R_PYTHON_TEST_ENV, set by
#   tools/python/CMakeLists.txt).
function(b21r_add_python_test name)
  cmake_parse_arguments(ARG "" "SCRIPT;TIMEOUT" "ARGS;LABELS" ${ARGN})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  get_filename_component(script "${ARG_SCRIPT}" ABSOLUTE)
  add_test(NAME ${name} COMMAND ${Python3_EXECUTABLE} "${script}" ${ARG_ARGS})
  get_property(py_env GLOBAL PROPERTY B21R_PYTHON_TEST_ENV)
  if(NOT py_env)
    set(py_env "PYTHONPATH=${CMAKE_BINARY_DIR}/python:${PROJECT_SOURCE_DIR}/tools" "PYTHONDONTWRITEBYTECODE=1" "B21R_BUILD_DIR=${CMAKE_BINARY_DIR}")
  endif()
  set_tests_properties(${name} PROPERTIES LABELS "unit;python;${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
    ENVIRONMENT "${py_env}")
endfunction()

# b21r_add_benchmark(<module>.<area> TARGET <exe> [ARGS ...])
#   Registers a benchmark executable under label "bench". Benchmarks print numbers; they fail only
#   on errors or when a target they check against an in-run reference is missed.
function(b21r_add_benchmark name)
  cmake_parse_arguments(ARG "" "TARGET;TIMEOUT" "ARGS" ${ARGN})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 900)
  endif()
  add_test(NAME ${name} COMMAND ${ARG_TARGET} ${ARG_ARGS})
  set_tests_properties(${name} PROPERTIES LABELS "bench" TIMEOUT ${ARG_TIMEOUT} RUN_SERIAL TRUE)
endfunction()

# b21r_add_instruction_budget(<module>.<area> TARGET <exe> [ARGS ...] [WITHIN <function>
#                             [EXCLUDE <function>...]] [TIMEOUT <s>])
#   Runs a benchmark under valgrind's callgrind (labels "bench" and "instructions"), which counts
#   instructions: the benchmark checks its budgets in instructions (test/bench/support/instr.h),
#   and a count does not change with the machine's load. Instrumentation starts where the
#   benchmark calls instr_start() (set-up before it runs uncounted, several times faster).
#   WITHIN counts only inside calls of that function, EXCLUDE leaves out calls of functions
#   inside it (a test double's work, say); both must not be inlined (callgrind's
#   --toggle-collect flips counting on at a call's entry and off at its exit).
function(b21r_add_instruction_budget name)
  cmake_parse_arguments(ARG "" "TARGET;TIMEOUT;WITHIN" "ARGS;EXCLUDE" ${ARGN})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 1800)
  endif()
  set(out "${CMAKE_CURRENT_BINARY_DIR}/${name}.callgrind")
  set(toggles)
  if(ARG_WITHIN)
    foreach(fn IN LISTS ARG_WITHIN ARG_EXCLUDE)
      list(APPEND toggles "--toggle-collect=${fn}")
    endforeach()
  endif()
  add_test(NAME ${name} COMMAND ${VALGRIND_EXECUTABLE} --tool=callgrind --instr-atstart=no --dump-instr=no
    --dump-line=no --callgrind-out-file=${out} ${toggles} $<TARGET_FILE:${ARG_TARGET}> ${ARG_ARGS})
  set_tests_properties(${name} PROPERTIES LABELS "bench;instructions" TIMEOUT ${ARG_TIMEOUT} RUN_SERIAL TRUE
    ENVIRONMENT "B21R_CALLGRIND_OUT=${out}")
endfunction()

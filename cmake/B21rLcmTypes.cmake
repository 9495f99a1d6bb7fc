# SPDX-License-Identifier: MIT
# b21r_lcm_types(<target> PACKAGE <pkg> TYPES <file.lcm>...)
# Runs lcm-gen at build time and produces:
#   <target>        C static library with the generated types (include as <pkg>_<type>.h)
#   <target>_python generated Python package under ${CMAKE_BINARY_DIR}/python/<pkg>
#   <target>_java   <pkg>-types.jar for lcm-spy (when a JDK and lcm.jar are available)
function(b21r_lcm_types target)
  cmake_parse_arguments(ARG "" "PACKAGE" "TYPES" ${ARGN})
  set(c_dir "${CMAKE_CURRENT_BINARY_DIR}/lcmgen/c")
  set(py_dir "${CMAKE_BINARY_DIR}/python")
  set(java_dir "${CMAKE_CURRENT_BINARY_DIR}/lcmgen/java")
  set(c_sources "")
  set(c_headers "")
  set(py_files "")
  set(java_files "")
  set(lcm_files "")
  foreach(lcm_file IN LISTS ARG_TYPES)
    get_filename_component(abs "${lcm_file}" ABSOLUTE)
    get_filename_component(type "${lcm_file}" NAME_WE)
    list(APPEND lcm_files "${abs}")
    list(APPEND c_sources "${c_dir}/${ARG_PACKAGE}_${type}.c")
    list(APPEND c_headers "${c_dir}/${ARG_PACKAGE}/${ARG_PACKAGE}_${type}.h")
    list(APPEND py_files "${py_dir}/${ARG_PACKAGE}/${type}.py")
    list(APPEND java_files "${java_dir}/${ARG_PACKAGE}/${type}.java")
  endforeach()

  # C: headers go under <pkg>/ so includes read <b21r/b21r_experience_t.h>.
  add_custom_command(
    OUTPUT ${c_sources} ${c_headers}
    COMMAND ${CMAKE_COMMAND} -E make_directory "${c_dir}/${ARG_PACKAGE}"
    COMMAND ${LCM_GEN_EXECUTABLE} --c --c-cpath "${c_dir}" --c-hpath "${c_dir}/${ARG_PACKAGE}"
            --cinclude "${ARG_PACKAGE}" ${lcm_files}
    DEPENDS ${lcm_files}
    COMMENT "lcm-gen (C): ${ARG_PACKAGE}"
    VERBATIM)
  add_library(${target} STATIC ${c_sources} ${c_headers})
  target_include_directories(${target} SYSTEM PUBLIC "${c_dir}")
  target_link_libraries(${target} PUBLIC b21r::lcm PRIVATE b21r_sanitizers)
  set_target_properties(${target} PROPERTIES POSITION_INDEPENDENT_CODE ON)

  # Python: for the tools (log readers, plots, experiment runners).
  add_custom_command(
    OUTPUT ${py_files} "${py_dir}/${ARG_PACKAGE}/__init__.py"
    COMMAND ${LCM_GEN_PYTHON_EXECUTABLE} --python --ppath "${py_dir}" ${lcm_files}
    DEPENDS ${lcm_files}
    COMMENT "lcm-gen (Python): ${ARG_PACKAGE}"
    VERBATIM)
  add_custom_target(${target}_python ALL DEPENDS ${py_files})

  # Java: a jar on lcm-spy's class path makes it decode our channels.
  if(B21R_BUILD_JAVA_TYPES AND Java_FOUND AND LCM_JAR)
    set(jar "${CMAKE_BINARY_DIR}/java/${ARG_PACKAGE}-types.jar")
    set(classes "${CMAKE_CURRENT_BINARY_DIR}/lcmgen/classes")
    add_custom_command(
      OUTPUT "${jar}"
      COMMAND ${CMAKE_COMMAND} -E rm -rf "${java_dir}" "${classes}"
      COMMAND ${CMAKE_COMMAND} -E make_directory "${java_dir}" "${classes}" "${CMAKE_BINARY_DIR}/java"
      COMMAND ${LCM_GEN_EXECUTABLE} --java --jpath "${java_dir}" ${lcm_files}
      COMMAND ${Java_JAVAC_EXECUTABLE} -nowarn -cp "${LCM_JAR}" -d "${classes}" ${java_files}
      COMMAND ${Java_JAR_EXECUTABLE} cf "${jar}" -C "${classes}" .
      DEPENDS ${lcm_files}
      COMMENT "lcm-gen (Java) + javac + jar: ${jar}"
      VERBATIM)
    add_custom_target(${target}_java ALL DEPENDS "${jar}")
    set_property(GLOBAL PROPERTY B21R_LCM_TYPES_JAR "${jar}")
  endif()
endfunction()

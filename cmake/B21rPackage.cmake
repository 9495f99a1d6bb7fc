# SPDX-License-Identifier: MIT
# The Debian package b21r-controller (CPack DEB, amd64 and arm64): what a robot needs on board.
# Install rules live beside their targets (firmware/app, tools); this file holds the package's
# metadata and the robot's configuration file. `cpack --preset robot|robot-arm64` after
# the build writes build/packages/b21r-controller_<version>_<arch>.deb (docs/robot.md).

# Debian's architecture name of the target (a cross build names its processor).
if(CMAKE_CROSSCOMPILING)
  if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64)$")
    set(B21R_DEB_ARCH arm64)
  elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|amd64)$")
    set(B21R_DEB_ARCH amd64)
  else()
    message(FATAL_ERROR "b21r: no Debian architecture known for ${CMAKE_SYSTEM_PROCESSOR}")
  endif()
else()
  execute_process(COMMAND dpkg --print-architecture OUTPUT_VARIABLE B21R_DEB_ARCH
    OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE _b21r_dpkg)
  if(NOT _b21r_dpkg EQUAL 0)
    set(B21R_DEB_ARCH amd64)
  endif()
endif()

# /etc/b21r/b21r-controller.conf: the reference configuration (every key with its documentation,
# firmware/app/b21r-controller.conf) with the service's settings. A key missing from the
# reference stops the configure step, so a renamed key cannot leave the package behind.
set(_b21r_ref "${PROJECT_SOURCE_DIR}/firmware/app/b21r-controller.conf")
set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS "${_b21r_ref}")
file(READ "${_b21r_ref}" _b21r_conf)
foreach(_kv IN ITEMS
    "rt_scheduler=fifo"
    "rt_lock_memory=true"
    "rt_prefault=true"
    "checkpoint_file=\"/var/lib/b21r/hedger.ckpt\""
    "operator_key_file=\"/etc/b21r/operator.key\"")
  string(REPLACE "=" ";" _kv "${_kv}")
  list(GET _kv 0 _key)
  list(GET _kv 1 _value)
  string(REGEX MATCH "\n${_key} = [^\n]*" _line "${_b21r_conf}")
  if(NOT _line)
    message(FATAL_ERROR "b21r: key ${_key} is not in ${_b21r_ref}: update cmake/B21rPackage.cmake")
  endif()
  string(REPLACE "${_line}" "\n${_key} = ${_value}" _b21r_conf "${_b21r_conf}")
endforeach()
set(B21R_ROBOT_CONF "${CMAKE_BINARY_DIR}/package/b21r-controller.conf")
file(WRITE "${B21R_ROBOT_CONF}.new"
  "# /etc/b21r/b21r-controller.conf: the settings of the b21r-controller service (docs/robot.md).\n"
  "# Every key with its documentation, allowed values and default (b21r-controller\n"
  "# --print-reference-config); the package sets these for the service: the tick thread at\n"
  "# SCHED_FIFO 50 with memory locked and pre-faulted (the unit's LimitRTPRIO/LimitMEMLOCK allow\n"
  "# it), the learned state in /var/lib/b21r, the operator key that postinst makes (copy it to the\n"
  "# operator's machine: docs/robot.md, \"The operator key\"). Set the devices below, then:\n"
  "#   systemctl enable --now b21r-controller\n\n"
  "${_b21r_conf}")
file(COPY_FILE "${B21R_ROBOT_CONF}.new" "${B21R_ROBOT_CONF}" ONLY_IF_DIFFERENT)
install(FILES "${B21R_ROBOT_CONF}" DESTINATION /etc/b21r COMPONENT robot)

set(_b21r_pkg "${PROJECT_SOURCE_DIR}/firmware/app/package")
install(FILES "${_b21r_pkg}/b21r-controller.service" DESTINATION /lib/systemd/system COMPONENT robot)
install(FILES "${_b21r_pkg}/b21r-controller.sysusers" DESTINATION lib/sysusers.d
  RENAME b21r-controller.conf COMPONENT robot)
install(FILES "${PROJECT_SOURCE_DIR}/docs/robot.md" DESTINATION share/doc/b21r-controller COMPONENT robot)

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME b21r-controller)
set(CPACK_PACKAGE_VERSION "${PROJECT_VERSION}")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "Onboard reinforcement-learning controller for the RWI B21r")
set(CPACK_PACKAGE_DESCRIPTION
  "The onboard controller of an RWI B21r mobile robot that learns its rotation-velocity policy with\n"
  "Q-learning and HEDGER (Smart & Kaelbling, ICRA 2002), as a systemd service with a watchdog,\n"
  "with the operator's teleop tool and log reader.")
string(REPLACE ";" "" CPACK_PACKAGE_DESCRIPTION "${CPACK_PACKAGE_DESCRIPTION}")
set(CPACK_PACKAGE_CONTACT "B21r controller maintainers <b21r@localhost>")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_COMPONENTS_ALL robot)
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_COMPONENTS_GROUPING ALL_COMPONENTS_IN_ONE)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_NAME b21r-controller)
set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE "${B21R_DEB_ARCH}")
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
# Stated by hand, the same for both architectures (a cross build cannot run dpkg-shlibdeps on the
# target's libraries): the controller's shared libraries (libc, libstdc++ for HEDGER, LCM and the
# GLib it needs), Debian's Python 3.11 for the tools (the LCM binding, which Debian does not
# package, ships inside, see tools/CMakeLists.txt), OpenSSL's libcrypto (the operator messages' HMAC),
# and systemd (sysusers, the unit).
# test/package checks them: the installed programs run in a fresh Debian 12 root.
set(CPACK_DEBIAN_PACKAGE_DEPENDS
  "libc6 (>= 2.36), libstdc++6 (>= 12), libgcc-s1, liblcm1 (>= 1.3.1), libglib2.0-0 (>= 2.74), libssl3 (>= 3.0), python3 (>= 3.11), systemd")
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "liblcm-bin")
set(CPACK_DEBIAN_PACKAGE_SUGGESTS "liblcm-java, default-jre")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
  "${_b21r_pkg}/postinst" "${_b21r_pkg}/prerm" "${_b21r_pkg}/postrm" "${_b21r_pkg}/conffiles")
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
set(CPACK_STRIP_FILES ON)
set(CPACK_OUTPUT_FILE_PREFIX "${CMAKE_BINARY_DIR}/packages")
include(CPack)

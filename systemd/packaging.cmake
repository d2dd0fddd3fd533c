# The Debian package: `cpack -G DEB` in a build directory (the release preset) writes
# pandarcap_VERSION_ARCH.deb with everything `cmake --install` puts under /usr, plus the
# maintainer scripts in systemd/debian/. Runtime dependencies come from dpkg-shlibdeps (the
# libraries the binaries actually link: libpcap, spdlog, fmt, libsystemd, Highway, libstdc++).
set(CPACK_GENERATOR "DEB")
set(CPACK_PACKAGE_NAME "pandarcap")
# The prefix the unit file was configured with (the package preset sets /usr).
set(CPACK_PACKAGING_INSTALL_PREFIX "${CMAKE_INSTALL_PREFIX}")
set(CPACK_PACKAGE_VENDOR "pandarcap")
set(CPACK_PACKAGE_CONTACT "pandarcap developers <dev@pandarcap.invalid>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "${PROJECT_DESCRIPTION}")
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION
    "pandarcapd receives the sensor's UDP packets with recvmmsg into a lock-free ring, decodes\n\
them with runtime-dispatched SIMD into preallocated frame arenas, and writes PCD frames, raw\n\
pcap recordings and per-second health (Prometheus textfile and JSON lines). Runs as the\n\
hardened template unit pandarcapd@NAME.service, one instance per sensor.")
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION "science")
set(CPACK_DEBIAN_PACKAGE_PRIORITY "optional")
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
# Cross-built (the package-arm64 preset): the package is for the target, not for the machine
# that built it (CPack would ask dpkg for this machine's architecture), and dpkg-shlibdeps finds
# the arm64 libraries' symbols files by the target's multiarch triplet. CPack strips with the
# target's strip.
if(CMAKE_CROSSCOMPILING AND CMAKE_SYSTEM_PROCESSOR STREQUAL "aarch64")
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE "arm64")
  set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS_PRIVATE_DIRS "/usr/lib/aarch64-linux-gnu")
endif()
# systemd-sysusers and systemd-tmpfiles run from the maintainer scripts; /bin/kill (procps)
# is the unit's ExecReload=.
set(CPACK_DEBIAN_PACKAGE_DEPENDS "systemd, procps")
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "prometheus-node-exporter")
# rclone: pandarcap-upload@NAME moves the recordings with it (docs/deploy.md).
set(CPACK_DEBIAN_PACKAGE_SUGGESTS "rclone, tcpdump, pcl-tools")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    "${PROJECT_SOURCE_DIR}/systemd/debian/postinst;${PROJECT_SOURCE_DIR}/systemd/debian/prerm;${PROJECT_SOURCE_DIR}/systemd/debian/postrm")
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
# Only what `install()` lists; the test and benchmark build trees stay out.
set(CPACK_STRIP_FILES ON)
include(CPack)

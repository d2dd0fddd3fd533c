# Cross-compiling for ARM64 (aarch64) on a Debian 12 x86-64 machine: Debian's cross toolchain
# (crossbuild-essential-arm64) and the arm64 multiarch -dev packages (dpkg --add-architecture
# arm64; .ci/install-deps --arm64 installs both). Binaries and tests run under QEMU's user-mode
# emulator: ctest through CMAKE_CROSSCOMPILING_EMULATOR, and the binaries the tests start (the
# daemon, pandarcap-ctl) through binfmt_misc, which qemu-user-static registers.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
# Multiarch: libraries in /usr/lib/aarch64-linux-gnu, their CMake packages beside them, and the
# pkg-config wrapper that reads only the arm64 .pc files.
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)
set(PKG_CONFIG_EXECUTABLE aarch64-linux-gnu-pkg-config CACHE FILEPATH "arm64 pkg-config")
# The CPU QEMU emulates comes from QEMU_CPU, which the binaries the tests start inherit too:
# "max" (NEON, SVE, SVE2; the arm64 test preset sets it), "max,sve-default-vector-length=16"
# for 128-bit SVE, "max,sve=off" for a NEON-only core (tests/CMakeLists.txt runs each).
set(CMAKE_CROSSCOMPILING_EMULATOR qemu-aarch64-static)

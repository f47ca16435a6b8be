#!/bin/sh
# The embedded tools of `make misra`, the Cortex-M build and its tests: cppcheck (MISRA addon),
# arm-none-eabi-gcc with newlib, qemu-system-arm, and cmake (the generated CMakeLists.txt).
# Debian/Ubuntu packages, installed with apt-get when it is available and we are root (CI);
# elsewhere it says what is missing and exits 0, and the tests that need a tool skip with a
# message naming it.
set -e
PACKAGES="cppcheck gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm cmake"
missing=""
command -v cppcheck >/dev/null 2>&1 || missing="$missing cppcheck"
command -v arm-none-eabi-gcc >/dev/null 2>&1 || missing="$missing gcc-arm-none-eabi libnewlib-arm-none-eabi"
command -v qemu-system-arm >/dev/null 2>&1 || missing="$missing qemu-system-arm"
command -v cmake >/dev/null 2>&1 || missing="$missing cmake"
if [ -z "$missing" ]; then
    exit 0
fi
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = "0" ]; then
    echo "installing embedded tools:$missing"
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $PACKAGES >/dev/null \
        || { DEBIAN_FRONTEND=noninteractive apt-get update >/dev/null && \
             DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $PACKAGES >/dev/null; }
else
    echo "embedded tools missing:$missing (install: sudo apt-get install $PACKAGES); their tests will skip"
fi

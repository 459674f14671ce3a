#!/usr/bin/env bash
# Installs the Cortex-M tools that firmware_c/ and its tests need: the GNU Arm cross compiler
# (gcc-arm-none-eabi), newlib with semihosting (libnewlib-arm-none-eabi) and QEMU's Arm system
# emulator (qemu-system-arm, board mps2-an386), and make. Debian packages, installed with apt-get.
# Idempotent and quiet; a no-op when everything is present. Never fails the caller: when it
# cannot install (not root, no apt-get, no package) it says so and exits 0, and the firmware
# tests skip with that message.
set -uo pipefail
have_newlib() {
  # rdimon.specs comes with libnewlib-arm-none-eabi; ask the compiler where its specs live.
  local specs
  specs=$(arm-none-eabi-gcc -print-file-name=rdimon.specs 2>/dev/null) || return 1
  [ -f "$specs" ]
}
find_missing() {
  missing=()
  command -v arm-none-eabi-gcc >/dev/null 2>&1 || missing+=(gcc-arm-none-eabi)
  if ! command -v arm-none-eabi-gcc >/dev/null 2>&1 || ! have_newlib; then
    missing+=(libnewlib-arm-none-eabi)
  fi
  command -v qemu-system-arm >/dev/null 2>&1 || missing+=(qemu-system-arm)
  command -v make >/dev/null 2>&1 || missing+=(make)
}
find_missing
[ ${#missing[@]} -eq 0 ] && exit 0
# Parallel callers (pytest -n 2 workers) wait for each other instead of fighting over apt's lock.
if command -v flock >/dev/null 2>&1; then
  exec 9>"${TMPDIR:-/tmp}/mems-tdc-install-arm-tools.lock"
  flock -w 1200 9 || true
  find_missing
  [ ${#missing[@]} -eq 0 ] && exit 0
fi
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "install_arm_tools: missing ${missing[*]} (not root or no apt-get); the Cortex-M tests will be skipped" >&2
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
echo "install_arm_tools: installing ${missing[*]} (apt-get, about a minute)" >&2
if ! apt-get install -y -qq -o DPkg::Lock::Timeout=600 --no-install-recommends "${missing[@]}" >/dev/null 2>&1; then
  # The package lists may be absent or stale on a fresh machine: refresh once and retry.
  apt-get update -qq >/dev/null 2>&1
  apt-get install -y -qq -o DPkg::Lock::Timeout=600 --no-install-recommends "${missing[@]}" >/dev/null 2>&1 \
    || echo "install_arm_tools: could not install ${missing[*]}; the Cortex-M tests will be skipped" >&2
fi
exit 0

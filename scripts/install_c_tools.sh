#!/usr/bin/env bash
# Installs the C tools the code generator's tests and benchmark need: clang (second compiler of the
# warning-free check) and valgrind (callgrind instruction counts). gcc is assumed present.
# Idempotent and fast when everything is there; installs with apt-get only when we are root.
# Never fails the caller: a tool that cannot be installed makes its tests skip with a message.
set -uo pipefail
missing=()
command -v clang >/dev/null 2>&1 || missing+=(clang)
command -v valgrind >/dev/null 2>&1 || missing+=(valgrind)
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "install_c_tools: missing ${missing[*]} (not root or no apt-get); their tests will be skipped" >&2
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
if ! apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null 2>&1; then
  # The package lists may be absent or stale on a fresh machine: refresh once and retry.
  apt-get update -qq >/dev/null 2>&1
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null 2>&1 \
    || echo "install_c_tools: could not install ${missing[*]}; their tests will be skipped" >&2
fi
exit 0

#!/bin/sh
# Installs Debian's `chromium` for the report test (tests/it/report_html.rs) when it is missing
# and this is root with apt; idempotent. Anywhere else it only says how: the test itself then
# fails, naming the same command, rather than skipping.
set -eu
if command -v chromium >/dev/null 2>&1 || [ -n "${SHAKEFLOW_CHROMIUM:-}" ]; then
  exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "installing chromium (apt-get) for the HTML report test"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium fonts-dejavu-core >/dev/null
else
  echo "note: chromium is missing and cannot be installed here (needs root and apt);" >&2
  echo "      install it with \`sudo apt-get install chromium\` or set SHAKEFLOW_CHROMIUM to a Chromium/Chrome binary," >&2
  echo "      else the report test fails" >&2
fi

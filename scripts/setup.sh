#!/usr/bin/env bash
# Set up ft-sitl on a fresh machine: a virtual environment in .venv with the package
# installed in editable mode. `--test` adds the test dependencies.
# Idempotent: re-running only installs what changed.
set -euo pipefail
cd "$(dirname "$0")/.."
extras=""
if [ "${1:-}" = "--test" ]; then
  extras="[test]"
  packages=""
  # the bus tests run a real MQTT broker: install mosquitto (Debian puts it in /usr/sbin)
  if ! command -v mosquitto >/dev/null 2>&1 && [ ! -x /usr/sbin/mosquitto ]; then
    packages="$packages mosquitto"
  fi
  # the report's browser test loads report.html in headless Chromium through its WebDriver
  if ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; then
    packages="$packages chromium chromium-driver"
  fi
  if [ -n "$packages" ]; then
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
    $sudo apt-get update -qq
    # shellcheck disable=SC2086  # one word per package
    $sudo apt-get install -y -qq $packages
  fi
fi
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --disable-pip-version-check --upgrade pip
.venv/bin/python -m pip install --quiet --disable-pip-version-check -e ".${extras}"

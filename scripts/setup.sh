#!/usr/bin/env bash
# One-shot set-up on a fresh Debian machine (root): the system library Open3D needs, uv, and the locked .venv.
# With --tests, also what the tests need: the dev and bench extras and Debian's chromium (the report test opens
# report.html in it headless; playwright drives it, no browser download). Idempotent: a second run only checks.
# Usage: bash scripts/setup.sh [--tests]
set -euo pipefail
cd "$(dirname "$0")/.."
TESTS=""
for arg in "$@"; do
    case "$arg" in
        --tests) TESTS=1 ;;
        *) echo "setup: unknown option '$arg' (use --tests)" >&2; exit 2 ;;
    esac
done

if [ "$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi
APT_UPDATED=""
apt_install() {  # apt_install PACKAGE WHY
    echo "setup: installing $1 ($2)"
    if [ -z "$APT_UPDATED" ]; then $SUDO apt-get update -qq; APT_UPDATED=1; fi
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "$1" >/dev/null
}

if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
    apt_install libusb-1.0-0 "needed by Open3D"
fi
if [ -n "$TESTS" ] && [ ! -x /usr/bin/chromium ]; then
    apt_install chromium "the headless browser of tests/test_report.py"
fi

if ! command -v uv >/dev/null 2>&1; then
    echo "setup: installing uv"
    python3 -m pip install -q --disable-pip-version-check uv
fi

# The lock file pins every package; --frozen refuses to drift from it. Byte-code is compiled here, once:
# where PYTHONDONTWRITEBYTECODE is set (this machine sets it) every process, each evaluator worker
# included, would otherwise compile every module it imports from source (benchmarks/README.md, "Start-up").
# --inexact: the tests' extras, once installed, stay when the main command's set-up runs after them.
if [ -n "$TESTS" ]; then EXTRAS="--extra dev --extra bench"; else EXTRAS=""; fi
# shellcheck disable=SC2086
uv sync --frozen --inexact $EXTRAS -q --compile-bytecode
.venv/bin/python -m compileall -q optipose >/dev/null
# The compiled kernels (numba) are cached beside their modules on first use: compiled here, once, so that a
# fresh clone's first command does not spend its first seconds on them (a second run finds them cached).
.venv/bin/python scripts/warm_kernels.py
echo "setup: ready (.venv/bin/optipose)"

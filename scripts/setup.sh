#!/usr/bin/env bash
# Set up everything mipray needs to build, test and render, on Debian 12.
#
#   scripts/setup.sh        (run by `make render`, `make test`, `make build`)
#
# Idempotent, and skips what is already there:
#   1. Debian packages: OpenSubdiv, OpenImageIO (+ tools), OpenEXR, CMake,
#      pkg-config, and python3-venv if `python3 -m venv` cannot work;
#      `apt-get update` runs only if something is missing; sudo only if not root.
#   2. .venv/ (python3 -m venv) if missing.
#   3. Python packages from scripts/requirements.txt, unless a stamp in .venv
#      says this exact file is installed and the imports work.
#   4. The extension mipray._mipray, built with `maturin develop` (dev profile)
#      into .venv, so .venv/bin/mipray-record and `import mipray` work.
#
# Environment: PYTHON (default python3), VENV (default .venv),
# MIPRAY_SKIP_APT=1 to skip step 1, MIPRAY_SKIP_BUILD=1 to skip step 4.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
ROOT=$(pwd)
VENV=${VENV:-$ROOT/.venv}
PYTHON=${PYTHON:-python3}
REQUIREMENTS=$ROOT/scripts/requirements.txt
APT_PACKAGES=(libosd-dev libopenimageio-dev openimageio-tools libopenexr-dev cmake pkg-config)

log() { printf 'setup: %s\n' "$*" >&2; }
die() { printf 'setup: error: %s\n' "$*" >&2; exit 1; }

# --- 0. toolchains -----------------------------------------------------------
if ! command -v cargo >/dev/null 2>&1 && [ -f "$HOME/.cargo/env" ]; then
    # shellcheck disable=SC1091
    . "$HOME/.cargo/env"
fi
command -v cargo >/dev/null 2>&1 || die "cargo not found: install Rust with rustup (https://rustup.rs)"
command -v "$PYTHON" >/dev/null 2>&1 || die "$PYTHON not found: install Python 3.11 or newer"
"$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
    || die "$PYTHON is $("$PYTHON" -V 2>&1); mipray needs Python 3.11 or newer"

# --- 1. Debian packages ------------------------------------------------------
if [ "${MIPRAY_SKIP_APT:-0}" = 1 ]; then
    log "skipping system packages (MIPRAY_SKIP_APT=1)"
elif ! command -v dpkg >/dev/null 2>&1; then
    log "no dpkg: not a Debian system; install by hand: ${APT_PACKAGES[*]}"
else
    missing=()
    for pkg in "${APT_PACKAGES[@]}"; do
        dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
    done
    if [ ! -x "$VENV/bin/python" ] && ! "$PYTHON" -c 'import ensurepip, venv' >/dev/null 2>&1; then
        missing+=("python3-venv")
    fi
    if [ "${#missing[@]}" -gt 0 ]; then
        SUDO=()
        if [ "$(id -u)" -ne 0 ]; then
            command -v sudo >/dev/null 2>&1 || die "need root or sudo to install: ${missing[*]}"
            SUDO=(sudo)
        fi
        log "installing Debian packages: ${missing[*]}"
        "${SUDO[@]}" apt-get update -qq
        DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
    else
        log "Debian packages present"
    fi
fi

# --- 2. virtual environment --------------------------------------------------
if [ ! -x "$VENV/bin/python" ]; then
    log "creating $VENV"
    "$PYTHON" -m venv "$VENV"
fi
VPY=$VENV/bin/python

# --- 3. Python packages ------------------------------------------------------
STAMP=$VENV/.mipray-requirements.sha256
want=$(sha256sum "$REQUIREMENTS" | cut -d' ' -f1)
have=$(cat "$STAMP" 2>/dev/null || true)
if [ "$want" = "$have" ] && [ -x "$VENV/bin/maturin" ] \
    && "$VPY" -c 'import numpy, pytest, pxr.Usd' >/dev/null 2>&1; then
    log "Python packages present"
else
    log "installing Python packages from scripts/requirements.txt"
    "$VPY" -m pip install --disable-pip-version-check -q -r "$REQUIREMENTS"
    echo "$want" > "$STAMP"
fi

# --- 4. the extension --------------------------------------------------------
if [ "${MIPRAY_SKIP_BUILD:-0}" = 1 ]; then
    log "skipping the extension build (MIPRAY_SKIP_BUILD=1)"
    exit 0
fi
[ -f "$ROOT/python/Cargo.toml" ] || die "python/Cargo.toml is missing: cannot build mipray._mipray"
BUILD_LOG=$VENV/.mipray-build.log
log "building mipray._mipray (maturin develop, dev profile; log in $BUILD_LOG)"
# The workspace's dev profile already optimises the hot crates (Cargo.toml).
if ! VIRTUAL_ENV=$VENV PATH="$VENV/bin:$PATH" \
    "$VENV/bin/maturin" develop -m "$ROOT/python/Cargo.toml" > "$BUILD_LOG" 2>&1; then
    tail -n 40 "$BUILD_LOG" >&2
    die "maturin develop failed (full log: $BUILD_LOG)"
fi
"$VPY" -c 'import mipray._mipray' \
    || die "mipray._mipray was built but does not import"
log "ready: $VENV/bin/mipray-record, $VPY -c 'import mipray'"

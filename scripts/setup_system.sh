#!/usr/bin/env bash
# Install the Debian packages of a package list if any is missing.
# Usage: scripts/setup_system.sh [LIST]   (default: requirements/debian-packages.txt, the solver's)
# Idempotent: does nothing (and needs no root) when everything is installed.
# Used by the Makefile and by the Dockerfiles in docker/, so all read the same lists.
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
list="${1:-$here/requirements/debian-packages.txt}"
mapfile -t pkgs < <(sed -e 's/#.*//' -e 's/[[:space:]]//g' "$list" | grep -v '^$')

missing=()
for p in "${pkgs[@]}"; do
    status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
    [[ "$status" == "install ok installed" ]] || missing+=("$p")
done
if [[ ${#missing[@]} -eq 0 ]]; then
    echo "setup-system: all ${#pkgs[@]} Debian packages of $(basename "$list") present"
    exit 0
fi

echo "setup-system: installing ${#missing[@]} Debian package(s): ${missing[*]}"
if [[ $(id -u) -ne 0 ]]; then
    if command -v sudo >/dev/null && sudo -n true 2>/dev/null; then
        SUDO=sudo
    else
        cat >&2 <<MSG

setup-system: these Debian packages are missing and installing them needs root:
    ${missing[*]}
Run, as root or with sudo:
    apt-get update && apt-get install -y --no-install-recommends ${missing[*]}
then run make again. (The list lives in $list.)
MSG
        exit 2
    fi
else
    SUDO=
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"

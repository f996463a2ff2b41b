#!/usr/bin/env bash
# Installs what building, testing and the demo need, and only what is missing:
# running it again on a ready machine changes nothing and takes a second.
# Debian 12 packages through apt-get, Python packages through pip.
set -euo pipefail

log() { echo "[install_deps] $*"; }

SUDO=""
if [[ $(id -u) -ne 0 ]]; then
  SUDO="sudo"
fi

# Debian packages: the build toolchain, the libraries the C++ code links, and
# the COLMAP command line used for feature extraction and reconstruction.
apt_packages=(
  cmake g++ make pkg-config
  libeigen3-dev libceres-dev libsqlite3-dev libboost-program-options-dev
  googletest libgtest-dev
  colmap
  python3
  # MPI: several processes (or machines) split one matching run
  openmpi-bin libopenmpi-dev
)

missing=()
for pkg in "${apt_packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done

# Python: numpy and Pillow render the demo scene; pycolmap is pinned so that
# every machine reads databases and models with the same version.
python_missing=()
python3 -c "import numpy" 2>/dev/null || python_missing+=(numpy)
python3 -c "import PIL" 2>/dev/null || python_missing+=(pillow)
python3 -c "import matplotlib" 2>/dev/null || python_missing+=(matplotlib)  # accuracy report plots
# pybind11 and scikit-build-core build the Python module (pip install .),
# pytest runs its tests.
python3 -c "import pybind11" 2>/dev/null || python_missing+=(pybind11)
python3 -c "import scikit_build_core" 2>/dev/null || python_missing+=(scikit-build-core)
python3 -c "import pytest" 2>/dev/null || python_missing+=(pytest)
if ! python3 -c "import pycolmap, sys; sys.exit(pycolmap.__version__ != '4.2.1')" 2>/dev/null; then
  python_missing+=("pycolmap==4.2.1")
fi
if [[ ${#python_missing[@]} -gt 0 ]] && ! python3 -m pip --version >/dev/null 2>&1; then
  missing+=(python3-pip)
fi

if [[ ${#missing[@]} -gt 0 ]]; then
  log "apt-get install ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  log "Debian packages: all present"
fi

if [[ ${#python_missing[@]} -gt 0 ]]; then
  log "pip install ${python_missing[*]}"
  # Debian's own python refuses pip installs without this flag; a pyenv or
  # venv python ignores it.
  PIP_BREAK_SYSTEM_PACKAGES=1 python3 -m pip install --quiet --disable-pip-version-check \
    "${python_missing[@]}"
else
  log "Python packages: all present"
fi

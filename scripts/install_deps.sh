#!/usr/bin/env bash
# Installs what building, testing and the demo need, and only what is missing:
# running it again on a ready machine changes nothing and takes a second.
# Debian 12 packages through apt-get, Python packages through pip.
# Environment:
#   CASHASH_PYCOLMAP  which pycolmap 4.2.1 wheel (scripts/compare_with_colmap.py
#                     runs COLMAP's matcher and mapper through it):
#                     cpu (default) the PyPI package pycolmap, CPU only;
#                     cuda12 the PyPI package pycolmap-cuda12, whose matcher
#                     runs on an NVIDIA GPU (replaces pycolmap);
#                     auto  cuda12 where nvidia-smi lists a GPU, else cpu.
set -euo pipefail

log() { echo "[install_deps] $*"; }

SUDO=""
if [[ $(id -u) -ne 0 ]]; then
  SUDO="sudo"
fi

# Debian packages: the build toolchain, the libraries the C++ code links, and
# the COLMAP command line used for feature extraction and reconstruction.
apt_packages=(
  cmake g++ make ninja-build pkg-config
  libeigen3-dev libsqlite3-dev libboost-program-options-dev
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
python3 -c "import lizard" 2>/dev/null || python_missing+=(lizard)  # CTest code_size_rules measures functions
pycolmap_kind="${CASHASH_PYCOLMAP:-cpu}"
if [[ "$pycolmap_kind" == auto ]]; then
  pycolmap_kind=cpu
  if command -v nvidia-smi >/dev/null && nvidia-smi -L 2>/dev/null | grep -q GPU; then
    pycolmap_kind=cuda12
  fi
fi
python_remove=()
case "$pycolmap_kind" in
  cpu)
    if ! python3 -c "import pycolmap, sys; sys.exit(pycolmap.__version__ != '4.2.1')" 2>/dev/null; then
      python_missing+=("pycolmap==4.2.1")
    fi ;;
  cuda12)
    # Both wheels install the module pycolmap: the CPU one goes first.
    if ! python3 -c "import pycolmap, sys; sys.exit(pycolmap.__version__ != '4.2.1' or not pycolmap.has_cuda)" \
        2>/dev/null; then
      python_missing+=("pycolmap-cuda12==4.2.1")
      if python3 -m pip show pycolmap >/dev/null 2>&1; then
        python_remove+=(pycolmap)
      fi
    fi ;;
  *)
    echo "CASHASH_PYCOLMAP must be cpu, cuda12 or auto, not '$pycolmap_kind'" >&2
    exit 1 ;;
esac
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

if [[ ${#python_remove[@]} -gt 0 ]]; then
  log "pip uninstall ${python_remove[*]} (replaced by the CUDA wheel)"
  PIP_BREAK_SYSTEM_PACKAGES=1 python3 -m pip uninstall --quiet --yes "${python_remove[@]}"
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

#!/usr/bin/env bash
# Installs what the project needs from Debian's archive (quiet and quick when present),
# then builds the C++ kernel module into pyfem/ (incremental: rebuilds only what changed).
#   scripts/setup.sh                  what runs and the default test tier need
#   scripts/setup.sh --with-paraview  also ParaView's Python and a virtual X server, and python3-venv
#                                     for the install test (slow tier)
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(
  g++ cmake make libgtest-dev pybind11-dev libopenmpi-dev openmpi-bin
  python3-dolfinx-real python3-petsc4py python3-mpi4py python3-gmsh python3-meshio
  python3-numpy python3-scipy python3-matplotlib python3-h5py python3-tqdm python3-pytest
  python3-pytest-xdist
)
if [ "${1:-}" = "--with-paraview" ]; then
  packages+=(paraview python3-paraview xvfb xauth python3-venv)
fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  sudo_cmd=""
  [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# The kernel: cmake reconfigures and rebuilds only when sources changed.
if [ ! -f build/CMakeCache.txt ]; then
  cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DPython3_EXECUTABLE=/usr/bin/python3 >/dev/null
fi
cmake --build build -j2 2>&1 | grep -E "error|warning|Error" || true
test -n "$(ls pyfem/_kernels*.so 2>/dev/null)" || { echo "setup: kernel module was not built" >&2; exit 1; }

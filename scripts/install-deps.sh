#!/usr/bin/env bash
# Installs every Debian 12 package the build, the tests and `make run` need.
# Idempotent: packages already present are skipped, and apt-get update runs only
# when something is missing. The CUDA toolkit is not a Debian 12 package at the
# version we need (13); the build uses nvcc when it finds one (COLLIDO_CUDA=AUTO).
set -euo pipefail

packages=(
  build-essential cmake pkg-config git
  libgtest-dev libgmock-dev            # tests
  libeigen3-dev                        # optional linear algebra (gvm baselines)
  nlohmann-json3-dev                   # JSON config, logs, model files
  libassimp-dev                        # OBJ/PLY/... import (mesh_import target only)
  libosmesa6-dev                       # offscreen OpenGL (render)
  libavcodec-dev libavformat-dev libavutil-dev libswscale-dev   # video (render)
  libfreetype-dev fonts-dejavu-core    # text overlay font (render)
  libpng-dev                           # PNG frames (render)
  libpistache-dev                      # the REST service's HTTP server (service)
  libsqlite3-dev                       # the service's embedded store
  libsodium-dev                        # Argon2id password hashes, session tokens (service)
  libcurl4-openssl-dev                 # the service tests' HTTP client
  chromium                             # browser tests of the web UI (headless)
  wrk                                  # HTTP load benchmark (bench/)
  python3-matplotlib                   # the study's charts (bench/study_charts.py)
  slurmctld slurmd slurm-client munge  # the Slurm executor and its single-node test
)
# The web UI's packages (scripts/install-web.sh) need node and npm: Debian's,
# unless a node with npm is already installed (e.g. from NodeSource).
command -v npm >/dev/null 2>&1 || packages+=(nodejs npm)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if ((${#missing[@]})); then
  echo "install-deps: installing ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "install-deps: all ${#packages[@]} packages present"
fi

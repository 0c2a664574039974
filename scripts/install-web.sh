#!/bin/sh
# Installs the browser UI's libraries, pinned by web/package-lock.json, and
# copies the files the pages load into web/static/vendor/ (served at
# /ui/vendor/). Also installs the browser tests' tools (playwright-core,
# axe-core); the tests drive the system's Chromium, so no browser is downloaded.
# Both web/node_modules/ and web/static/vendor/ are git-ignored: run this after
# a checkout, and again when web/package-lock.json changes.
set -eu
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root/web"

# Nothing to do when the lock file is the one last installed and the copies are there.
stamp=node_modules/.collido-installed-lock
if [ -f "$stamp" ] && cmp -s "$stamp" package-lock.json && [ -f static/vendor/three/three.module.js ]; then
  echo "install-web: web/node_modules matches web/package-lock.json"
  exit 0
fi

# --ignore-scripts: none of these packages needs an install script, and none runs.
npm ci --ignore-scripts --no-audit --no-fund

vendor=static/vendor
rm -rf "$vendor"
mkdir -p "$vendor/three/addons/loaders" "$vendor/three/addons/controls" "$vendor/uplot"
nm=node_modules
cp "$nm/three/build/three.module.js" "$nm/three/build/three.core.js" "$nm/three/LICENSE" "$vendor/three/"
cp "$nm/three/examples/jsm/loaders/STLLoader.js" "$vendor/three/addons/loaders/"
cp "$nm/three/examples/jsm/controls/OrbitControls.js" "$vendor/three/addons/controls/"
cp "$nm/uplot/dist/uPlot.esm.js" "$nm/uplot/dist/uPlot.min.css" "$nm/uplot/LICENSE" "$vendor/uplot/"
echo "install-web: $(cd "$vendor" && find . -type f | wc -l) files in web/$vendor"
cp package-lock.json "$stamp"

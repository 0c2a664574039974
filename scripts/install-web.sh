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

# npm ci only when the lock file is not the one last installed.
stamp=node_modules/.collido-installed-lock
if [ -f "$stamp" ] && cmp -s "$stamp" package-lock.json && [ -d node_modules/three ]; then
  echo "install-web: web/node_modules matches web/package-lock.json"
else
  # --ignore-scripts: none of these packages needs an install script, and none runs.
  npm ci --ignore-scripts --no-audit --no-fund
  cp package-lock.json "$stamp"
fi

# The copies are made every time (a dozen files): a change to this list takes
# effect at the next run, whatever was installed before.
vendor=static/vendor
rm -rf "$vendor"
mkdir -p "$vendor/three/addons/loaders" "$vendor/three/addons/controls" "$vendor/uplot"
nm=node_modules
cp "$nm/three/build/three.module.js" "$nm/three/build/three.core.js" "$nm/three/LICENSE" "$vendor/three/"
# three's add-ons import the bare name 'three', which a browser resolves only
# through an import map (an inline script); pointed at the file instead, the
# pages need no inline script at all.
for f in loaders/STLLoader.js controls/OrbitControls.js; do
  sed "s#from 'three';#from '../../three.module.js';#" "$nm/three/examples/jsm/$f" > "$vendor/three/addons/$f"
  if grep -q "from 'three'" "$vendor/three/addons/$f"; then
    echo "install-web: $f still imports 'three' by its bare name" >&2
    exit 1
  fi
done
cp "$nm/uplot/dist/uPlot.esm.js" "$nm/uplot/dist/uPlot.min.css" "$nm/uplot/LICENSE" "$vendor/uplot/"
# gzip copies beside the scripts and styles, which the service sends to a
# browser that takes gzip (three.js: 2.1 MB, 0.4 MB so). -k keeps the file and
# gives the copy its time; the service skips a copy older than its file.
find "$vendor" -type f \( -name '*.js' -o -name '*.css' \) -exec gzip -9 -k -n -f {} +
# The study's charts (committed under docs/img/study/) for the methods page.
rm -rf static/study
for set in cpu gpu; do
  if [ -d "$root/docs/img/study/$set" ]; then
    mkdir -p "static/study/$set"
    cp "$root/docs/img/study/$set/"*.png "$root/docs/img/study/$set/summary.json" "static/study/$set/"
  fi
done
echo "install-web: $(cd "$vendor" && find . -type f ! -name '*.gz' | wc -l) files in web/$vendor, study charts: $(find static/study -name '*.png' 2>/dev/null | wc -l)"

#!/usr/bin/env bash
# The demo: installs what it needs, builds, fetches the sample scan (Stanford dragon), packs it
# and renders an orbit of views to PNG under out/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
bash scripts/fetch_sample.sh
mkdir -p out
./build/scanatlas pack data/samples/dragon_vrip.ply -o out/dragon.hfa
./build/scanatlas info out/dragon.hfa
./build/scanatlas render out/dragon.hfa --orbit 8 --size 1024x1024 -o out/dragon.png
if [ -f ../shared/data/stanford_bunny/scans/bun.conf ]; then
  ./build/scanatlas pack ../shared/data/stanford_bunny/scans/bun.conf -o out/bunny.hfa
  ./build/scanatlas render out/bunny.hfa --orbit 8 --size 1024x1024 -o out/bunny.png
fi
echo "demo: views written to out/ (dragon_0.png .. dragon_7.png)"

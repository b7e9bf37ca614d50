#!/usr/bin/env bash
# Builds the libFuzzer targets (clang + ASan + UBSan) into build-fuzz/ and runs each for
# SECONDS (default 30) on seed corpora made from real files (../shared/data) and tiny
# hand-made inputs. Crashes are saved as build-fuzz/crash-*; turn each into a regression test.
# Usage: scripts/fuzz.sh [SECONDS]
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-30}
bash scripts/deps.sh
command -v clang++ >/dev/null || { SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"; $SUDO apt-get install -y -qq clang libclang-rt-14-dev >/dev/null; }
dpkg-query -W libclang-rt-14-dev >/dev/null 2>&1 || { SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"; $SUDO apt-get install -y -qq libclang-rt-14-dev >/dev/null; }
CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSCANATLAS_FUZZ=ON \
  -DCMAKE_CXX_COMPILER_LAUNCHER= -DCMAKE_C_COMPILER_LAUNCHER= >/dev/null
cmake --build build-fuzz -j"${JOBS:-2}"
seeds=build-fuzz/seeds
rm -rf "$seeds"; mkdir -p "$seeds"/{ply,las,text,pack}
data=../shared/data
# Seeds: the heads of real files (libFuzzer mutates from there) plus small complete inputs.
if [ -d "$data" ]; then
  head -c 6000 "$data/stanford_bunny/scans/bun000.ply" > "$seeds/ply/bun000_head.ply"
  head -c 6000 "$data/stanford_dragon/scans_stand/dragonStandRight_0.ply" > "$seeds/ply/dragon_bye_head.ply"
  head -c 6000 "$data/igea/igea.ply" > "$seeds/ply/igea_head.ply"
  head -c 4000 "$data/stanford_bunny/reconstruction/bun_zipper_res4.ply" > "$seeds/ply/zipper_head.ply"
  head -c 6000 "$data/lidar/autzen_trim.las" > "$seeds/las/autzen_head.las"
  head -c 6000 "$data/lidar/lone-star.las" > "$seeds/las/lonestar_head.las"
  cp "$data/stanford_bunny/scans/bun.conf" "$seeds/text/bun.conf"
fi
printf 'ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n' > "$seeds/ply/tri.ply"
printf 'ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0\0\0\200?\0\0\0\0\0\0\0\0' > "$seeds/ply/bin.ply"
printf '3\n0 0 0 10 1 2 3\n1 0 0 10 1 2 3\n0 1 0 10 1 2 3\n' > "$seeds/text/a.pts"
printf 'x,y,z,r,g,b\n0,0,0,1,2,3\n1,1,1,4,5,6\n' > "$seeds/text/a.csv"
if [ -x build/scanatlas ]; then
  printf 'ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0.1\n' > "$seeds/tiny.ply"
  ./build/scanatlas pack "$seeds/tiny.ply" -o "$seeds/pack/tiny.hfa" -q --force
  rm -f "$seeds/tiny.ply"
fi
status=0
for t in ply las text pack; do
  mkdir -p build-fuzz/corpus/$t
  echo "== fuzz_$t for ${secs}s" >&2
  if ! (cd build-fuzz && ./fuzz_$t -max_total_time="$secs" -max_len=16384 -timeout=10 -rss_limit_mb=2048 \
        -print_final_stats=1 corpus/$t seeds/$t 2>&1 | tail -n 12); then
    status=1
  fi
done
exit $status

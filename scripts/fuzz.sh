#!/usr/bin/env bash
# Builds the libFuzzer targets (clang + ASan + UBSan) into build-fuzz/ and runs each for
# SECONDS (default 30) on seed corpora made from real files (../shared/data) and tiny
# hand-made inputs. Crashes are saved as build-fuzz/crash-*; turn each into a regression test
# (fuzz/regressions/<target>/, replayed by formats_test FuzzRegressions.*).
# Usage: scripts/fuzz.sh [SECONDS]     (TARGETS="pcd draco" limits the targets)
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
rm -f build-fuzz/crash-* build-fuzz/oom-* build-fuzz/timeout-* build-fuzz/leak-*
rm -rf "$seeds"; mkdir -p "$seeds"/{ply,las,text,pack,pcd,draco,mesh}
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
  head -c 6000 "$data/pcd/table_scene_mug_stereo_textured.pcd" > "$seeds/pcd/mug_head.pcd"
fi
# PCD seeds in all three encodings. The binary_compressed one holds a valid LZF block made of
# literal runs (control byte = run length - 1, then the bytes).
printf 'VERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n0 0 0 255\n1 nan 2 65280\n' > "$seeds/pcd/a.pcd"
/usr/bin/python3 - "$seeds/pcd" <<'PY'
import struct, sys
d = sys.argv[1]
hdr = "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA {}\n"
pts = [(0, 0, 0, 1), (1, 0, 0, 2), (float("nan"), 0, 0, 3), (0, 1, 0.5, 4)]
body = b"".join(struct.pack("<fffH", *p) for p in pts)
open(d + "/b.pcd", "wb").write(hdr.format("binary").encode() + body)
soa = b"".join(struct.pack("<f", p[0]) for p in pts) + b"".join(struct.pack("<f", p[1]) for p in pts) + \
      b"".join(struct.pack("<f", p[2]) for p in pts) + b"".join(struct.pack("<H", p[3]) for p in pts)
lzf = b""
for i in range(0, len(soa), 32):
    run = soa[i:i + 32]
    lzf += bytes([len(run) - 1]) + run
open(d + "/c.pcd", "wb").write(hdr.format("binary_compressed").encode() + struct.pack("<II", len(lzf), len(soa)) + lzf)
PY
printf 'ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n' > "$seeds/ply/tri.ply"
printf 'ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0\0\0\200?\0\0\0\0\0\0\0\0' > "$seeds/ply/bin.ply"
printf 'OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0.5\n3 0 1 2\n3 1 3 2\n' > "$seeds/mesh/a.off"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.5\nvn 0 0 1\nf 1 2 3\nf 2 4 3\n' > "$seeds/mesh/a.obj"
printf 'solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n' > "$seeds/mesh/a.stl"
printf '3\n0 0 0 10 1 2 3\n1 0 0 10 1 2 3\n0 1 0 10 1 2 3\n' > "$seeds/text/a.pts"
printf 'x,y,z,r,g,b\n0,0,0,1,2,3\n1,1,1,4,5,6\n' > "$seeds/text/a.csv"
if [ -x build/scanatlas ]; then
  printf 'ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0.1\n' > "$seeds/tiny.ply"
  ./build/scanatlas pack "$seeds/tiny.ply" -o "$seeds/pack/tiny.hfa" -q --force
  ./build/scanatlas pack "$seeds/tiny.ply" -o "$seeds/pack/tiny_raw.hfa" -q --force --raw-pages
  # One cell of about 37 x 35 texels: its level 4 stored (MIPZ).
  ./build/scanatlas pack "$seeds/ply/tri.ply" -o "$seeds/pack/tri_levels.hfa" -q --force --texel-size 0.03
  ./build/scanatlas convert "$seeds/tiny.ply" -o "$seeds/draco/tiny.drc" -q
  ./build/scanatlas convert "$seeds/tiny.ply" -o "$seeds/draco/tiny_lossless.drc" --quantization 0 -q
  ./build/scanatlas convert "$seeds/ply/tri.ply" -o "$seeds/draco/tri_mesh.drc" -q
  rm -f "$seeds/tiny.ply"
fi
status=0
for t in ${TARGETS:-ply las text pack pcd draco mesh}; do
  mkdir -p build-fuzz/corpus/$t
  echo "== fuzz_$t for ${secs}s" >&2
  extra=()
  # Stored findings run first on every fuzz run, so a regression fails here too.
  regress=(); [ -d "fuzz/regressions/$t" ] && regress=("../fuzz/regressions/$t")
  # libdraco allocates gigabytes for some small hostile inputs (production decodes in a child
  # process under a memory limit, see formats/draco.h): keep fuzzing past those out-of-memory
  # reports; crashes still stop the run and fail it.
  [ "$t" = draco ] && extra=(-fork=2 -ignore_ooms=1)
  # OpenMesh's OBJ reader aborts on assertions for some malformed files (production reads
  # meshes in a child process): keep going, then replay every artifact below.
  [ "$t" = mesh ] && extra=(-fork=2 -ignore_ooms=1 -ignore_crashes=1)
  if ! (cd build-fuzz && ./fuzz_$t "${extra[@]}" -max_total_time="$secs" -max_len=16384 -timeout=10 -rss_limit_mb=2048 \
        -print_final_stats=1 corpus/$t seeds/$t "${regress[@]}" 2>&1 | tail -n 12); then
    # draco and mesh: the libraries' own crashes are expected (fork mode goes on past them and
    # exits non-zero); the artifact replay below decides.
    if [ "$t" != draco ] && [ "$t" != mesh ]; then status=1; fi
  fi
done
# Artifacts of the targets that fuzz third-party readers in process must all be clean
# bad-input errors (exit 2) through the product, which runs those readers in a child process.
if [ -x build/scanatlas ]; then
  for f in build-fuzz/crash-* build-fuzz/oom-* build-fuzz/timeout-*; do
    [ -e "$f" ] || continue
    for ext in drc obj off stl; do
      cp "$f" "build-fuzz/replay.$ext"
      # A reader child that loops is stopped after 20 s of CPU (exit 2), inside the 60 s timeout.
      code=0; SA_READER_CPU_S=20 timeout 60 ./build/scanatlas info "build-fuzz/replay.$ext" >/dev/null 2>&1 || code=$?
      if [ "$code" -ne 2 ] && [ "$code" -ne 0 ]; then
        echo "fuzz.sh: $f as .$ext: scanatlas info exited $code (expected 0 or 2)" >&2; status=1
      fi
    done
  done
  echo "fuzz.sh: replayed $(ls build-fuzz/crash-* build-fuzz/oom-* build-fuzz/timeout-* 2>/dev/null | wc -l) artifact(s) through scanatlas info" >&2
fi
exit $status

#!/usr/bin/env bash
# Peak memory and time of `scanatlas pack` for the largest real file of each input format
# (../shared/data), plus the Draco sizes of each: the table in the issue-5 closing note and
# docs/FORMATS.md. Formats without a real file here (Draco, text, OBJ) are made from the
# largest real file by `scanatlas convert` (Draco, text) or awk (OBJ from the ascii PLY).
# Usage: scripts/formats_memory.sh   (after scripts/build.sh; writes out/formats/)
set -euo pipefail
cd "$(dirname "$0")/.."
B=./build/scanatlas
D=../shared/data
O=out/formats
mkdir -p "$O"
[ -x "$B" ] || { echo "build first: scripts/build.sh" >&2; exit 1; }
$B convert "$D/stanford_dragon/reconstruction/dragon_vrip.ply" -o "$O/dragon_vrip.drc" -q
$B convert "$D/lidar/lone-star.las" -o "$O/lone-star.xyz" -q
if [ ! -s "$O/dragon_vrip.obj" ]; then
  awk 'BEGIN{h=1} h&&/^element vertex/{nv=$3} h&&/^end_header/{h=0;next} h{next}
       nv>0{print "v",$1,$2,$3; nv--; next} $1==3{print "f",$2+1,$3+1,$4+1}' \
    "$D/stanford_dragon/reconstruction/dragon_vrip.ply" > "$O/dragon_vrip.obj"
fi
row() {  # format, input...
  local fmt=$1; shift
  local bytes=0 f
  for f in "$@"; do
    case "$f" in *.conf) for s in $(awk '$1=="bmesh"{print $2}' "$f"); do bytes=$((bytes + $(stat -c %s "$(dirname "$f")/$s"))); done;;
                 *) bytes=$((bytes + $(stat -c %s "$f")));; esac
  done
  local t
  t=$( { /usr/bin/time -f "%M %e" $B pack "$@" -o "$O/x.hfa" --force -q; } 2>&1 | tail -1)
  local rss=${t% *} secs=${t#* }
  local pts
  pts=$($B info "$O/x.hfa" --json | /usr/bin/python3 -c 'import json,sys; j=json.load(sys.stdin); print(j["source_points"], j["bytes"])')
  printf '| %s | %s | %.1f | %s | %.1f | %s | %.1f |\n' "$fmt" "$(basename "$1")" "$(echo "$bytes / 1048576" | bc -l)" \
    "${pts% *}" "$(echo "${pts#* } / 1048576" | bc -l)" "$secs" "$(echo "$rss / 1024" | bc -l)"
}
echo "| format | largest file | input MiB | points | pack MiB | pack s | peak RSS MiB |"
echo "|---|---|---:|---:|---:|---:|---:|"
row "PLY mesh (ascii)" "$D/stanford_dragon/reconstruction/dragon_vrip.ply"
row "PLY binary, tristrips" "$D/igea/igea.ply"
row ".conf scan set (15 range PLYs)" "$D/stanford_dragon/scans_stand/dragonStandRight.conf"
row "LAS 1.1 fmt 1" "$D/lidar/lone-star.las"
row "PCD binary_compressed" "$D/pcd/table_scene_mug_stereo_textured.pcd"
row "Draco mesh (from dragon_vrip)" "$O/dragon_vrip.drc"
row "XYZ text (from lone-star)" "$O/lone-star.xyz"
row "OBJ (from dragon_vrip)" "$O/dragon_vrip.obj"
echo
echo "Draco sizes (scanatlas convert IN -o OUT.drc --quantization Q), beside the pack:"
echo "| file | input MiB | pack MiB | drc q11 MiB | drc q14 MiB | drc q16 MiB | drc lossless MiB |"
echo "|---|---:|---:|---:|---:|---:|---:|"
for f in "$D/stanford_dragon/reconstruction/dragon_vrip.ply" "$D/lidar/lone-star.las" "$D/lidar/autzen_trim.las" \
         "$D/pcd/table_scene_mug_stereo_textured.pcd" "$D/stanford_bunny/scans/bun.conf"; do
  $B pack "$f" -o "$O/y.hfa" -q --force
  line="| $(basename "$f") | $(printf %.2f "$(echo "$(du -bc $( [ "${f##*.}" = conf ] && awk -v d="$(dirname "$f")" '$1=="bmesh"{print d"/"$2}' "$f" || echo "$f") | tail -1 | cut -f1) / 1048576" | bc -l)") | $(printf %.2f "$(echo "$(stat -c %s "$O/y.hfa") / 1048576" | bc -l)")"
  for q in 11 14 16 0; do
    b=$($B convert "$f" -o "$O/q.drc" --quantization $q --json | /usr/bin/python3 -c 'import json,sys; print(json.load(sys.stdin)["bytes"])')
    line="$line | $(printf %.2f "$(echo "$b / 1048576" | bc -l)")"
  done
  echo "$line |"
done

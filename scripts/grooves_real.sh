#!/usr/bin/env bash
# Runs `scanatlas grooves` on every scan in ../shared/data and on a generated scan with known
# grooves, draws what it finds over a shaded view of the points (docs/images/grooves_*.jpg) and
# prints a table (markdown) of counts, lengths and times. usage: scripts/grooves_real.sh [OUTDIR]
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/grooves}
img=docs/images
mkdir -p "$out" "$img"
sa=build/scanatlas
data=../shared/data
command -v /usr/bin/python3 >/dev/null && /usr/bin/python3 -c "import numpy, matplotlib" 2>/dev/null || {
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get install -y -qq python3-matplotlib >/dev/null
}
build/sa_gen_grooves "$out/synthetic.ply" "$out/synthetic_truth.json" >/dev/null
# name | input | view
runs=(
  "synthetic|$out/synthetic.ply|auto"
  "igea|$data/igea/igea.ply|auto"
  "bunny_scans|$data/stanford_bunny/scans/bun.conf|z"
  "bunny_mesh|$data/stanford_bunny/reconstruction/bun_zipper.ply|z"
  "dragon_scans|$data/stanford_dragon/scans_stand/dragonStandRight.conf|z"
  "dragon_mesh|$data/stanford_dragon/reconstruction/dragon_vrip.ply|z"
  "mug|$data/pcd/table_scene_mug_stereo_textured.pcd|-y"
  "autzen|$data/lidar/autzen_trim.las|z"
  "lone_star|$data/lidar/lone-star.las|z"
)
echo "| scan | points | grooves | of them gaps | total length | spacing | noise | regions (not a height field) | seconds |"
echo "|---|---|---|---|---|---|---|---|---|"
for r in "${runs[@]}"; do
  IFS='|' read -r name input view <<<"$r"
  line=$($sa grooves "$input" --json "$out/$name.json" --csv "$out/$name.csv" --quiet 2>/dev/null | head -1)
  $sa convert "$input" -o "$out/$name.xyz" >/dev/null 2>&1
  # An image where something was found.
  if ! grep -q '"grooves": \[\]' "$out/$name.json"; then
    /usr/bin/python3 scripts/plot_grooves.py "$out/$name.xyz" "$out/$name.json" "$img/grooves_$name.jpg" \
      --view="$view" --title "$name" --size 900
  fi
  /usr/bin/python3 - "$out/$name.json" "$out/$name.xyz" "$line" "$name" <<'EOF'
import json, re, sys
g = json.load(open(sys.argv[1]))
pts = sum(1 for _ in open(sys.argv[2])) - 1
line = sys.argv[3]
secs = re.search(r"in ([0-9.]+) s", line).group(1)
reg = re.search(r"(\d+) regions, (\d+) not", line)
gaps = sum(1 for x in g["grooves"] if x["shape"] == "gap")
total = sum(x["length"] for x in g["grooves"])
print(f"| {sys.argv[4]} | {pts} | {len(g['grooves'])} | {gaps} | {total:.4g} | {g['spacing']:.3g} | {g['noise']:.3g} | "
      f"{reg.group(1)} ({reg.group(2)}) | {secs} |")
EOF
done

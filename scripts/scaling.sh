#!/usr/bin/env bash
# Frame cost vs point count (Lu, Low & Zheng's O(F + B) claim): the same bumpy sphere sampled
# at 1M, 4M and 16M points (tools/gen_surface), packed with the same texel budget, benched
# with parallax and the points baseline over the same orbit. Prints a table and writes
# out/scaling.csv. Usage: scripts/scaling.sh [SIZE (default 1024x1024)] [FRAMES (default 30)]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh >/dev/null
size=${1:-1024x1024}
frames=${2:-30}
work=$(mktemp -d "${TMPDIR:-/tmp}/scanatlas-scaling-XXXXXX")
trap 'rm -rf "$work"' EXIT
mkdir -p out
echo "points,parallax_cpu_ms,points_cpu_ms,cells,texels" > out/scaling.csv
for n in 1000000 4000000 16000000; do
  ./build/sa_gen_surface "$n" "$work/s.ply"
  ./build/scanatlas pack "$work/s.ply" -o "$work/s.hfa" --texels 4M -q
  cells=$(./build/scanatlas info "$work/s.hfa" --json | /usr/bin/python3 -c 'import json,sys; d=json.load(sys.stdin); print(d["cells"], d["texels"])')
  ./build/scanatlas bench "$work/s.hfa" --orbit 12 --size "$size" --warmup 3 --frames "$frames" \
      --mode parallax,points --json > "$work/b.json"
  /usr/bin/python3 - "$n" "$cells" "$work/b.json" >> out/scaling.csv <<'PY'
import json, sys
n, cells, path = sys.argv[1], sys.argv[2].split(), sys.argv[3]
d = json.load(open(path))
t = {c["mode"]: c["cpu_ms"]["median"] for c in d["configs"]}
print(f"{n},{t['parallax']:.2f},{t['points']:.2f},{cells[0]},{cells[1]}")
PY
  rm -f "$work/s.ply" "$work/s.hfa"
done
/usr/bin/python3 - <<'PY'
import csv
rows = list(csv.DictReader(open("out/scaling.csv")))
print(f"{'points':>10} {'parallax ms':>12} {'points ms':>10} {'cells':>6} {'texels':>9}")
for r in rows:
    print(f"{int(r['points']):>10} {float(r['parallax_cpu_ms']):>12.1f} {float(r['points_cpu_ms']):>10.1f} {r['cells']:>6} {r['texels']:>9}")
a, b = rows[0], rows[-1]
print(f"16M/1M median frame time: parallax {float(b['parallax_cpu_ms'])/float(a['parallax_cpu_ms']):.2f}, "
      f"points {float(b['points_cpu_ms'])/float(a['points_cpu_ms']):.2f}")
PY

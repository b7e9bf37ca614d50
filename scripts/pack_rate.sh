#!/usr/bin/env bash
# Packing throughput on the synthetic survey (tools/gen_terrain: terrain + buildings,
# georeferenced, RGB): the LAS without normals (normals estimated) and the same scene as PLY with
# normals. Prints points/s, the pack's phase seconds and the cores each phase kept busy (its CPU
# seconds over its wall seconds, from pack --json), peak RSS, CPU use of the whole run (user+sys
# over wall, of `nproc` cores) and the cells; writes out/pack_rate.csv.
# Usage: scripts/pack_rate.sh [POINTS, default 2000000] [extra pack options...]
set -euo pipefail
cd "$(dirname "$0")/.."
n=${1:-2000000}
shift || true
bash scripts/build.sh >/dev/null
work=$(mktemp -d "${TMPDIR:-/tmp}/scanatlas-rate-XXXXXX")
trap 'rm -rf "$work"' EXIT
mkdir -p out
echo "input,points,seconds,mpts_per_s,count_s,distribute_s,normals_octree_s,heightmaps_s,write_s,count_cores,distribute_cores,normals_octree_cores,heightmaps_cores,write_cores,peak_rss_mb,cpu_use,cells,forced" > out/pack_rate.csv
for ext in las ply; do
  ./build/sa_gen_terrain "$n" "$work/survey.$ext"
  /usr/bin/time -f "%M %U %S %e" -o "$work/time.txt" ./build/scanatlas pack "$work/survey.$ext" -o "$work/s.hfa" --force --json "$@" > "$work/info.json"
  /usr/bin/python3 - "$ext" "$n" "$work/info.json" "$work/time.txt" "$(nproc)" >> out/pack_rate.csv <<'PY'
import json, sys
ext, n, info, tm, cores = sys.argv[1], int(sys.argv[2]), json.load(open(sys.argv[3])), open(sys.argv[4]).read().split(), int(sys.argv[5])
rss, user, sys_, wall = int(tm[0]) / 1024, float(tm[1]), float(tm[2]), float(tm[3])
s, c = info["seconds"], info["cpu_seconds"]
total = s["total"]
phases = ["count", "distribute", "octree", "heightmaps", "write"]
busy = ",".join(f"{c[p] / s[p]:.2f}" if s[p] > 0 else "0" for p in phases)
print(f"{ext},{n},{total:.2f},{n / total / 1e6:.3f},{s['count']:.2f},{s['distribute']:.2f},{s['octree']:.2f},{s['heightmaps']:.2f},"
      f"{s['write']:.2f},{busy},{rss:.0f},{(user + sys_) / wall / cores:.2f},{info['cells']},{info['forced_cells']}")
PY
  rm -f "$work/survey.$ext" "$work/s.hfa"
done
/usr/bin/python3 - <<'PY'
import csv
rows = list(csv.DictReader(open("out/pack_rate.csv")))
print(f"{'input':<6} {'points':>10} {'s':>7} {'Mpts/s':>7} {'count':>6} {'distr':>6} {'norm+oct':>8} {'heightm':>8} {'write':>6} {'cores: norm+oct':>15} {'heightm':>7} {'RSS MB':>7} {'CPU':>5} {'cells':>7} {'forced':>7}")
for r in rows:
    print(f"{r['input']:<6} {int(r['points']):>10} {float(r['seconds']):>7.2f} {float(r['mpts_per_s']):>7.3f} {float(r['count_s']):>6.2f} "
          f"{float(r['distribute_s']):>6.2f} {float(r['normals_octree_s']):>8.2f} {float(r['heightmaps_s']):>8.2f} {float(r['write_s']):>6.2f} "
          f"{float(r['normals_octree_cores']):>15.2f} {float(r['heightmaps_cores']):>7.2f} {float(r['peak_rss_mb']):>7.0f} {float(r['cpu_use']):>5.2f} {r['cells']:>7} {r['forced']:>7}")
PY

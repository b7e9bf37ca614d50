#!/usr/bin/env bash
# Reproduces the tables of docs/BENCHMARKS.md: packs the bunny (10 raw scans) and the dragon
# (vrip mesh), measures error against their references and frame times with scanatlas eval
# (parallax at 4, 8, 12, 16 steps and the points baseline; 8 orbit views at 1024x1024) and the
# effect of each skip with scanatlas bench --compare-skips. Writes out/bench/*.{csv,json,png,svg}
# and out/bench/tables.md. Needs ../shared/data beside the checkout and python3-matplotlib.
# Usage: scripts/bench.sh [FRAMES per bench configuration, default 40]
set -euo pipefail
cd "$(dirname "$0")/.."
frames=${1:-40}
bash scripts/build.sh >/dev/null
if ! /usr/bin/python3 -c 'import matplotlib' 2>/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get install -y -qq python3-matplotlib >/dev/null
fi
data=../shared/data
out=out/bench
mkdir -p "$out"
sa=./build/scanatlas
$sa pack "$data/stanford_bunny/scans/bun.conf" -o "$out/bunny.hfa" -q
$sa pack "$data/stanford_dragon/reconstruction/dragon_vrip.ply" -o "$out/dragon.hfa" -q
declare -A ref=([bunny]="$data/stanford_bunny/reconstruction/bun_zipper.ply"
                [dragon]="$data/stanford_dragon/reconstruction/dragon_vrip.ply")
for m in bunny dragon; do
  echo "== eval $m" >&2
  $sa eval "$out/$m.hfa" --reference "${ref[$m]}" --orbit 8 --size 1024x1024 --mode parallax,points \
      --iterations 4,8,12,16 --csv "$out/eval_$m.csv" --plot "$out/tradeoff_$m.png" --json > "$out/eval_$m.json"
  echo "== bench $m" >&2
  $sa bench "$out/$m.hfa" --orbit 24 --size 1024x1024 --warmup 4 --frames "$frames" --mode parallax,points \
      --iterations 12 --compare-skips --csv "$out/bench_$m.csv" --json > "$out/bench_$m.json"
  $sa info "$out/$m.hfa" --json > "$out/info_$m.json"
done
# Where the skips matter: close-ups (most boxes outside the view) and far views (boxes
# under a pixel), dragon, 512x512.
for z in 4 0.05; do
  echo "== bench dragon --zoom $z" >&2
  $sa bench "$out/dragon.hfa" --orbit 12 --zoom "$z" --size 512x512 --warmup 2 --frames "$frames" \
      --iterations 12 --compare-skips --json > "$out/bench_dragon_zoom$z.json"
done
/usr/bin/python3 - "$out" <<'PY' > "$out/tables.md"
import json, sys
out = sys.argv[1]
for m in ("bunny", "dragon"):
    info = json.load(open(f"{out}/info_{m}.json"))
    ev = json.load(open(f"{out}/eval_{m}.json"))
    be = json.load(open(f"{out}/bench_{m}.json"))
    print(f"### {m}: {info['source_points']} source points, {info['cells']} cells, {info['texels']} texels, "
          f"{info['bytes'] / 2**20:.1f} MiB\n")
    print(f"Reference: {ev['reference']}; {ev['views']} orbit views at {ev['width']}x{ev['height']}; {ev['renderer']}.\n")
    print("| mode | steps | frame ms (median) | IoU (mean / min) | silhouette err | depth err median | depth err p95 | normal err median | PSNR dB |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for c in ev["configs"]:
        nm = "-" if c["normal_median_deg"] is None else f"{c['normal_median_deg']:.1f}°"
        it = "-" if c["mode"] == "points" else c["iterations"]
        print(f"| {c['mode']} | {it} | {c['frame_ms']:.1f} | {c['iou']:.4f} / {c['iou_min']:.4f} | {c['silhouette_error']:.3f} | "
              f"{100 * c['depth_median']:.4f}% | {100 * c['depth_p95']:.3f}% | {nm} | {c['psnr']:.2f} |")
    print(f"\nSkips (bench, {be['cameras']} orbit cameras, {be['frames']} frames each, {be['width']}x{be['height']}):\n")
    print("| mode | skips on | cpu ms median | p95 | p99 | gpu ms median | boxes drawn | splats | fragments |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for c in be["configs"]:
        print(f"| {c['mode']} | {c['skips']} | {c['cpu_ms']['median']:.1f} | {c['cpu_ms']['p95']:.1f} | {c['cpu_ms']['p99']:.1f} | "
              f"{c['gpu_ms']['median']:.1f} | {c['boxes_drawn']:.0f} | {c['splats']:.0f} | {c['fragments']:.0f} |")
    print()
for z in ("4", "0.05"):
    be = json.load(open(f"{out}/bench_dragon_zoom{z}.json"))
    print(f"### dragon, orbit --zoom {z} ({be['cameras']} cameras, {be['frames']} frames each, {be['width']}x{be['height']})\n")
    print("| skips on | cpu ms median | p95 | boxes drawn | culled | splats | fragments |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for c in be["configs"]:
        print(f"| {c['skips']} | {c['cpu_ms']['median']:.1f} | {c['cpu_ms']['p95']:.1f} | {c['boxes_drawn']:.0f} | "
              f"{c['boxes_culled']:.0f} | {c['splats']:.0f} | {c['fragments']:.0f} |")
    print()
PY
cat "$out/tables.md"

#!/usr/bin/env bash
# The surface-detail modes side by side (docs/BENCHMARKS.md, "Modes"): packs the bunny (10 raw
# scans) and the dragon (vrip mesh) with the exact mode's maxima, bakes vdm under a byte budget and gdm,
# then per mode (slices: 16 a cell): bytes (section on disk, on the GPU, per texel), bake seconds, frame time
# (bench, 8 orbit views), error against the reference (eval) and the work counters.
# Writes out/modes/*.{json,csv,png,svg} and out/modes/table.md.
# Usage: scripts/bench_modes.sh [SIZE, default 768] [VDM BUDGET, default 64M]
set -euo pipefail
cd "$(dirname "$0")/.."
size=${1:-768}
budget=${2:-64M}
slices=16
bash scripts/build.sh >/dev/null
if ! /usr/bin/python3 -c 'import matplotlib' 2>/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get install -y -qq python3-matplotlib >/dev/null
fi
data=../shared/data
out=out/modes
mkdir -p "$out"
sa=./build/scanatlas
declare -A src=([bunny]="$data/stanford_bunny/scans/bun.conf" [dragon]="$data/stanford_dragon/reconstruction/dragon_vrip.ply")
declare -A ref=([bunny]="$data/stanford_bunny/reconstruction/bun_zipper.ply"
                [dragon]="$data/stanford_dragon/reconstruction/dragon_vrip.ply")
for m in bunny dragon; do
  $sa pack "${src[$m]}" -o "$out/$m.hfa" --modes exact -q
  $sa bake "$out/$m.hfa" --mode vdm --budget "$budget" --force -q
  $sa bake "$out/$m.hfa" --mode gdm --force -q
  $sa info "$out/$m.hfa" --json > "$out/info_$m.json"
  echo "== bench $m" >&2
  $sa bench "$out/$m.hfa" --orbit 8 --size "${size}x${size}" --warmup 2 --frames 16 --mode parallax,exact,vdm,gdm,slices --slices "$slices" \
      --iterations 12,64 --json > "$out/bench_$m.json"
  echo "== eval $m" >&2
  $sa eval "$out/$m.hfa" --reference "${ref[$m]}" --orbit 8 --size "${size}x${size}" --repeat 1 --mode parallax,exact,vdm,gdm,slices --slices "$slices" \
      --iterations 12,64 --csv "$out/eval_$m.csv" --plot "$out/tradeoff_$m.png" --json > "$out/eval_$m.json"
  # gdm where cells are forced, parallax's own programs elsewhere (--gdm-elsewhere parallax)
  $sa bench "$out/$m.hfa" --orbit 8 --size "${size}x${size}" --warmup 2 --frames 16 --mode gdm --gdm-elsewhere parallax \
      --iterations 12 --json > "$out/bench_gp_$m.json"
  $sa eval "$out/$m.hfa" --reference "${ref[$m]}" --orbit 8 --size "${size}x${size}" --repeat 1 --mode gdm --gdm-elsewhere parallax \
      --iterations 12 --json > "$out/eval_gp_$m.json"
done
/usr/bin/python3 - "$out" "$slices" <<'PY' > "$out/table.md"
import json, sys
out = sys.argv[1]
for m in ("bunny", "dragon"):
    info = json.load(open(f"{out}/info_{m}.json"))
    bench = json.load(open(f"{out}/bench_{m}.json"))
    ev = json.load(open(f"{out}/eval_{m}.json"))
    texels = info["texels"]
    modes = {x["mode"]: x for x in info["modes"]}
    print(f"\n{m}: {texels} texels, pack {info['bytes'] / 2**20:.1f} MiB, renderer {bench['renderer']}, "
          f"{bench['cameras']} views at {bench['width']}x{bench['height']}\n")
    print("| mode | iters (slices) | section MiB | B/texel | GPU MiB (mode) | bake s | frame ms | IoU | depth med % | depth p95 % "
          "| normal deg | work/ray mean (p99) | lookups falling back |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    gp_bench = json.load(open(f"{out}/bench_gp_{m}.json"))["configs"]
    gp_eval = json.load(open(f"{out}/eval_gp_{m}.json"))["configs"]
    for c in gp_bench:
        c["mode"] = c["drawn_mode"] = "gdm+parallax"
    ev["configs"] += gp_eval
    for c in bench["configs"] + gp_bench:
        name = c["mode"]
        stepped = name in ("parallax", "gdm+parallax")
        it = c["iterations"] if stepped else "-"
        e = next((r for r in ev["configs"] if r["mode"] == c["drawn_mode"] and (not stepped or r["iterations"] == c["iterations"])), None)
        sec = modes.get(name.split("+")[0], {})
        mib = c["mode_disk_bytes"] / 2**20
        w = c.get("work", {})
        fb = f"{100 * w['fallbacks'] / w['lookups']:.1f} %" if w.get("lookups") else "-"
        err = (f"{e['iou']:.4f} | {100 * e['depth_median']:.4f} | {100 * e['depth_p95']:.4f} | {e['normal_median_deg']:.2f}"
               if e else "- | - | - | -")
        work = f"{w['mean']:.1f} ({w['p99']})" if w.get("rays") else "-"  # slices cast nothing: no counters
        if name == "slices":
            it = sys.argv[2]
        print(f"| {name} | {it} | {mib:.1f} | {c['mode_disk_bytes'] / texels:.2f} | {c['mode_gpu_bytes'] / 2**20:.1f} | "
              f"{sec.get('bake_s', 0):.1f} | {c['cpu_ms']['median']:.1f} | {err} | {work} | {fb} |")
PY
cat "$out/table.md"

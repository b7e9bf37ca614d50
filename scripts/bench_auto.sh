#!/usr/bin/env bash
# The auto mode (level of detail) on a far orbit of the synthetic survey: frame times of parallax
# and auto (bench --compare-skips), and each one's image error against the exact mode (coverage
# IoU, depth error in pixel footprints against auto's bound of sqrt(3), colour PSNR).
# usage: scripts/bench_auto.sh [POINTS (default 20000000)] [SIZE (768)] [AUTO_PIXELS (8)]
set -euo pipefail
cd "$(dirname "$0")/.."
n=${1:-20000000}
size=${2:-768}
px=${3:-8}
out=out/auto
mkdir -p "$out/r"
sa=build/scanatlas
/usr/bin/python3 -c "import numpy, PIL" 2>/dev/null || {
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get install -y -qq python3-numpy python3-pil >/dev/null
}
[ -f "$out/t$n.las" ] || build/sa_gen_terrain "$n" "$out/t$n.las"
$sa pack "$out/t$n.las" -o "$out/t$n.hfa" --quiet
$sa bake "$out/t$n.hfa" --mode exact | tail -1
$sa bench "$out/t$n.hfa" --orbit 8 --size "${size}x$size" --warmup 2 --frames 8 --iterations 12 --compare-skips \
  --auto-pixels "$px" --json > "$out/bench.json"
for m in exact parallax auto; do
  $sa render "$out/t$n.hfa" --orbit 4 --size "${size}x$size" --mode $m --iterations 12 --auto-pixels "$px" \
    -o "$out/r/$m.png" --depth-out "$out/r/$m.pfm" 2>/dev/null
done
/usr/bin/python3 - "$out" "$size" <<'EOF'
import json, math, sys
import numpy as np
from PIL import Image
out, size = sys.argv[1], int(sys.argv[2])
def pfm(f):
    with open(f, "rb") as fh:
        fh.readline(); w, h = map(int, fh.readline().split()); s = float(fh.readline())
        return np.frombuffer(fh.read(), dtype="<f4" if s < 0 else ">f4").reshape(h, w)
b = json.load(open(f"{out}/bench.json"))
ms = {c["skips"]: c["cpu_ms"]["median"] for c in b["configs"]}
print(f"frame median (ms): parallax-12 {ms['all']:.1f}, auto {ms['all+auto-slices']:.1f} "
      f"({100 * (1 - ms['all+auto-slices'] / ms['all']):.0f} % less)")
angle = 2 * math.tan(math.radians(20)) / size  # the default 40 degree field of view
for m in ["parallax", "auto"]:
    iou, within, psnr = [], [], []
    for i in range(4):
        ref, d = pfm(f"{out}/r/exact_{i}.pfm"), pfm(f"{out}/r/{m}_{i}.pfm")
        a, c = np.isfinite(ref), np.isfinite(d)
        iou.append((a & c).sum() / (a | c).sum())
        e = np.abs(d[a & c] - ref[a & c]) / (ref[a & c] * angle)
        within.append((e <= math.sqrt(3)).mean())
        x = np.asarray(Image.open(f"{out}/r/exact_{i}.png").convert("RGB"), float)
        y = np.asarray(Image.open(f"{out}/r/{m}_{i}.png").convert("RGB"), float)
        psnr.append(10 * math.log10(255 ** 2 / max(((x - y) ** 2).mean(), 1e-12)))
    print(f"{m:8s} vs exact: IoU {min(iou):.4f}-{max(iou):.4f}, depth within sqrt(3) pixel footprints on "
          f"{100 * min(within):.2f}-{100 * max(within):.2f} % of common pixels, PSNR {min(psnr):.1f}-{max(psnr):.1f} dB")
EOF

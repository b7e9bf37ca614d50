#!/usr/bin/env bash
# The grooves mode's frame cost: a 2000 x 2000 gently curved wall (a mesh, 5 units between
# vertices) with N random grooves given (polylines of 3-6 points, 10-60 long, 1.5-6 wide, V and
# U, 0.3-2 deep, some crossing), packed once, baked with --grooves, then `scanatlas bench` of
# parallax (the wall alone) against grooves on the same orbit (the whole wall in view: grooves
# under a pixel wide, anti-aliased) and 4 and 16 times closer.
# Prints the frame-time ratios (interleaved frames, means) and the section's bytes per groove.
# usage: scripts/bench_grooves.sh [N] [SIZE]     (defaults 1000, 768)
set -euo pipefail
cd "$(dirname "$0")/.."
n=${1:-1000}
size=${2:-768}
out=out/grooves_bench
mkdir -p "$out"
sa=build/scanatlas
/usr/bin/python3 - "$out" "$n" <<'PY'
import json, math, random, sys
out, n = sys.argv[1], int(sys.argv[2])
random.seed(3)
side, step = 2000, 5.0
m = int(side / step)
with open(out + "/wall.ply", "w") as f:
    f.write("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\n" % ((m + 1) ** 2))
    f.write("element face %d\nproperty list uchar int vertex_indices\nend_header\n" % (2 * m * m))
    for j in range(m + 1):
        for i in range(m + 1):
            x, y = i * step, j * step
            f.write("%g %g %g\n" % (x, y, 10 * math.sin(x / 300) * math.cos(y / 225)))
    for j in range(m):
        for i in range(m):
            q = j * (m + 1) + i
            f.write("3 %d %d %d\n3 %d %d %d\n" % (q, q + 1, q + m + 2, q, q + m + 2, q + m + 1))
grooves = []
for k in range(n):
    x, y = random.uniform(20, side - 20), random.uniform(20, side - 20)
    a = random.uniform(0, 2 * math.pi)
    pts = []
    for p in range(random.randint(3, 6)):
        pts.append([x, y, 10 * math.sin(x / 300) * math.cos(y / 225)])
        l = random.uniform(10, 60) / 5
        a += random.uniform(-0.5, 0.5)
        x = min(max(x + l * math.cos(a), 1), side - 1)
        y = min(max(y + l * math.sin(a), 1), side - 1)
    w = random.uniform(1.5, 6)
    grooves.append({"polyline": pts, "width": w, "depth": random.uniform(0.3, 2), "shape": random.choice(["V", "U"])})
json.dump({"format": "scanatlas-grooves", "version": 1, "spacing": 1.0, "grooves": grooves}, open(out + "/grooves.json", "w"))
PY
$sa pack "$out/wall.ply" -o "$out/wall.hfa" -q
$sa bake "$out/wall.hfa" --mode grooves --grooves "$out/grooves.json" --force 2>&1 | tail -1
# The two modes' frames interleaved (bench --interleave): on a shared machine or llvmpipe the
# speed drifts by 10-20 % within a run, and one mode timed after the other moved the ratio by
# as much. The ratio is of the mean frame times (the 8 views differ in cost, and a median over
# them jumps between views).
for zoom in 1 4 16; do
  echo "== orbit 8 at ${size}x${size}, zoom $zoom"
  $sa bench "$out/wall.hfa" --orbit 8 --zoom $zoom --size ${size}x${size} --mode parallax,grooves --warmup 2 --frames 24 \
    --interleave --json > "$out/bench_zoom$zoom.json"
  /usr/bin/python3 - "$out/bench_zoom$zoom.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))["configs"]
for m in c:
    t = m["cpu_ms"]
    print("%-9s frame mean %.1f ms, median %.1f, p95 %.1f" % (m["mode"], t["mean"], t["median"], t["p95"]))
p, g = c[0]["cpu_ms"]["mean"], c[1]["cpu_ms"]["mean"]
print("grooves / parallax frame time (means): %.3f; pixels deferred a frame %.0f" % (g / p, c[1]["grooves"]["deferred_per_frame"]))
PY
done

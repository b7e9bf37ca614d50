#!/usr/bin/python3
"""Run-time vs error trade-off plot from `scanatlas eval --csv` summary rows.

usage: plot_tradeoff.py SUMMARY.csv OUT.png   (also writes OUT.svg)
Needs Debian's python3-matplotlib (scripts/deps.sh does not install it; eval --plot says so).
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    src, out = sys.argv[1], sys.argv[2]
    rows = [r for r in csv.DictReader(open(src)) if r.get("view") == "all"]
    if not rows:
        sys.exit("plot_tradeoff.py: no summary rows (view == all) in " + src)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    panels = [("depth_median", "median depth error (% of diagonal)", 100.0, True),
              ("iou", "coverage IoU", 1.0, False)]
    for ax, (key, label, scale, log) in zip(axes, panels):
        for mode in sorted({r["mode"] for r in rows}):
            pts = sorted(((float(r["frame_ms"]), float(r[key]) * scale, r["iterations"], r["skips"])
                          for r in rows if r["mode"] == mode), key=lambda p: p[0])
            xs, ys = [p[0] for p in pts], [p[1] for p in pts]
            ax.plot(xs, ys, marker="o", label=mode)
            for x, y, it, sk in pts:
                tag = ("" if it in ("", "0") else it + " it") + ("" if sk in ("all", "-") else " " + sk)
                if tag:
                    ax.annotate(tag, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
        ax.set_xlabel("median frame time (ms)")
        ax.set_ylabel(label)
        if log:
            ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
        ax.legend()
    pack = rows[0].get("pack", "")
    fig.suptitle("ScanAtlas run time vs error" + (" — " + os.path.basename(pack) if pack else ""))
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    fig.savefig(os.path.splitext(out)[0] + ".svg")


if __name__ == "__main__":
    main()

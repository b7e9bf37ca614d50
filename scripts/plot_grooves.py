#!/usr/bin/env python3
"""Draws detected grooves over a shaded orthographic view of a scan's points.

usage: plot_grooves.py POINTS.xyz GROOVES.json OUT.png [--view auto|x|-x|y|-y|z|-z] [--title T]
                       [--crop x0,y0,x1,y1]   (fractions of the view, to zoom in)

POINTS.xyz: `scanatlas convert SCAN -o POINTS.xyz`. The view looks along the given axis
(auto: the points' smallest principal axis). Each point is splatted into a depth buffer; the
image is hill-shaded from that depth. Grooves are drawn where they are visible (within a few
spacings of the depth buffer): red V/U (brighter = more confident), blue gaps (no points).
"""
import argparse
import json

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def view_basis(pts, view):
    if view == "auto":
        c = pts - pts.mean(axis=0)
        w, v = np.linalg.eigh(c.T @ c)
        d = v[:, 0]
    else:
        d = np.zeros(3)
        d["xyz".index(view[-1])] = -1.0 if view.startswith("-") else 1.0
    # Looking along -d: d points toward the viewer.
    up = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    right = np.cross(up, d)
    right /= np.linalg.norm(right)
    up = np.cross(d, right)
    return right, up, d


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("points")
    ap.add_argument("grooves")
    ap.add_argument("out")
    ap.add_argument("--view", default="auto")
    ap.add_argument("--title", default="")
    ap.add_argument("--crop", default="")
    ap.add_argument("--size", type=int, default=1400)
    a = ap.parse_args()
    pts = np.loadtxt(a.points, skiprows=1, usecols=(0, 1, 2))
    g = json.load(open(a.grooves))
    right, up, d = view_basis(pts, a.view)
    X, Y, Z = pts @ right, pts @ up, pts @ d
    x0, x1, y0, y1 = X.min(), X.max(), Y.min(), Y.max()
    if a.crop:
        c = [float(v) for v in a.crop.split(",")]
        x0, x1, y0, y1 = x0 + c[0] * (x1 - x0), x0 + c[2] * (x1 - x0), y0 + c[1] * (y1 - y0), y0 + c[3] * (y1 - y0)
    span = max(x1 - x0, y1 - y0)
    px = span / a.size
    W, H = int((x1 - x0) / px) + 1, int((y1 - y0) / px) + 1
    # Splat radius: about the sample spacing in pixels.
    spacing = g.get("spacing", px) or px
    r = max(1, int(round(spacing / px)))
    depth = np.full((H, W), -np.inf)
    ix = ((X - x0) / px).astype(int)
    iy = ((y1 - Y) / px).astype(int)
    keep = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
    ix, iy, Zk = ix[keep], iy[keep], Z[keep]
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            jx, jy = np.clip(ix + dx, 0, W - 1), np.clip(iy + dy, 0, H - 1)
            np.maximum.at(depth, (jy, jx), Zk)
    valid = np.isfinite(depth)
    dz = np.where(valid, depth, np.nan)
    gy, gx = np.gradient(dz / px)
    shade = np.clip(0.6 + 0.4 * (-gx * 0.5 + gy * 0.5) / np.sqrt(1 + gx ** 2 + gy ** 2), 0, 1)
    img = np.where(valid, np.nan_to_num(shade, nan=0.6), 1.0)
    fig = plt.figure(figsize=(W / 100, H / 100 + 0.6), dpi=100)
    ax = fig.add_axes([0, 0, 1, H / (H + 60)])
    ax.imshow(img, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    shown = 0
    for gr in g["grooves"]:
        P = np.array(gr["polyline"])
        u, v, z = (P @ right - x0) / px, (y1 - P @ up) / px, P @ d
        iu, iv = np.clip(u.astype(int), 0, W - 1), np.clip(v.astype(int), 0, H - 1)
        vis = valid[iv, iu] & (z >= depth[iv, iu] - 4 * spacing) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
        if not vis.any():
            continue
        shown += 1
        col = (0.1, 0.3, 1.0) if gr["shape"] == "gap" else (1.0, 0.15 * (1 - gr["confidence"]), 0.0)
        u = np.where(vis, u, np.nan)
        ax.plot(u, v, "-", color=col, lw=1.2, alpha=0.5 + 0.5 * gr["confidence"])
    ax.set_xlim(0, W)
    ax.set_ylim(H, 0)
    ax.axis("off")
    n = len(g["grooves"])
    gaps = sum(1 for x in g["grooves"] if x["shape"] == "gap")
    total = sum(x["length"] for x in g["grooves"])
    fig.text(0.01, 1 - 0.5 / (H / 100 + 0.6), f"{a.title}: {n} grooves ({gaps} gaps), {total:.4g} long, "
             f"{shown} visible from this side\nspacing {spacing:.3g}, noise {g.get('noise', 0):.3g}", fontsize=8)
    fig.savefig(a.out, **({"pil_kwargs": {"quality": 80}} if a.out.endswith(".jpg") else {}))


if __name__ == "__main__":
    main()

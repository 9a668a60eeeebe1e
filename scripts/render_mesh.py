#!/usr/bin/env python3
"""Renders a vesselhex mesh.vtu to PNG: the half of the vessel behind a plane through its axis,
so the lumen O-grid and the three wall layers show on the cut. Needs meshio, numpy, matplotlib.

usage: render_mesh.py MESH.vtu OUT.png [--title TEXT]
"""
import sys
from collections import Counter

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import meshio  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

# canonical hex faces, outward winding (src/mesh.rs HEX_FACES)
FACES = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
COLOURS = {0: (0.85, 0.30, 0.25), 1: (0.98, 0.85, 0.40), 2: (0.55, 0.75, 0.45), 3: (0.35, 0.55, 0.80)}


def half_cut(pts, hexes, region):
    """The faces of the half of the vessel behind a plane through its principal axis that are
    on no other element of that half (its outside and the cut), shaded, with the axis and the
    lateral direction of the cut (the cut plane's normal)."""
    centroids = pts[hexes].mean(axis=1)
    # principal axis of the vessel; the cut plane holds it and the second principal direction,
    # so it runs through every branch of a bifurcation or an arch (they spread in that plane)
    c0 = centroids.mean(axis=0)
    _, _, vt = np.linalg.svd(centroids - c0, full_matrices=False)
    axis, lateral = vt[0], vt[2]
    keep = (centroids - c0) @ lateral < 0
    counts = Counter()
    faces = []
    for h, r in zip(hexes[keep], region[keep]):
        for f in FACES:
            q = tuple(h[list(f)])
            counts[frozenset(q)] += 1
            faces.append((q, r))
    polys, colours = [], []
    light = np.array([0.3, -0.5, 0.8])
    light /= np.linalg.norm(light)
    for q, r in faces:
        if counts[frozenset(q)] != 1:
            continue
        p = pts[list(q)]
        n = np.cross(p[2] - p[0], p[3] - p[1])
        n /= np.linalg.norm(n) or 1.0
        shade = 0.45 + 0.55 * abs(n @ light)
        polys.append(p)
        colours.append(tuple(min(1.0, c * shade) for c in COLOURS[int(r)]))
    return polys, colours, axis, lateral


def draw_half_cut(ax, pts, hexes, region, title="cut along the axis", zoom=1.0):
    """Draws the half cut (see half_cut) on a 3D axes, looking at the cut face, magnified by
    `zoom`."""
    polys, colours, axis, lateral = half_cut(pts, hexes, region)
    ax.add_collection3d(Poly3DCollection(polys, facecolors=colours, edgecolors=(0, 0, 0, 0.35), linewidths=0.25))
    used = pts[np.unique(hexes)]
    lo, hi = used.min(axis=0), used.max(axis=0)
    centre, size = (lo + hi) / 2, (hi - lo).max() / 2
    for setlim, k in ((ax.set_xlim, 0), (ax.set_ylim, 1), (ax.set_zlim, 2)):
        setlim(centre[k] - size, centre[k] + size)
    # look at the cut face, slightly from the side
    view = lateral + 0.5 * np.cross(axis, lateral)
    ax.view_init(elev=np.degrees(np.arcsin(view[2] / np.linalg.norm(view))), azim=np.degrees(np.arctan2(view[1], view[0])))
    ax.set_box_aspect(None, zoom=zoom)
    ax.set_axis_off()
    ax.set_title(title)
    return axis, lateral


def main():
    path, out = sys.argv[1], sys.argv[2]
    title = sys.argv[sys.argv.index("--title") + 1] if "--title" in sys.argv else path
    mesh = meshio.read(path)
    pts = mesh.points
    hexes = np.asarray(mesh.cells_dict["hexahedron"], dtype=np.int64)
    region = mesh.cell_data_dict["region"]["hexahedron"]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    size = (hi - lo).max() / 2
    c0 = pts[hexes].mean(axis=1).mean(axis=0)
    fig = plt.figure(figsize=(11, 5.5), dpi=110)
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    axis, lateral = draw_half_cut(ax, pts, hexes, region)
    # the inlet section: the O-grid (core block, four lateral blocks) and the wall rings
    ax2 = fig.add_subplot(1, 2, 2)
    # cells whose bottom face (canonical nodes 0-3, the upstream side) lies in the end plane
    along = (pts - c0) @ axis
    ends = [along.min(), along.max()]
    bottom = along[hexes[:, :4]]
    first = np.zeros(len(hexes), dtype=bool)
    for e in ends:
        sel = np.all(np.abs(bottom - e) < 1e-6 * size, axis=1)
        if sel.any():
            first = sel
            break
    u = np.cross(axis, lateral)
    for h, r in zip(hexes[first], region[first]):
        p = pts[h[:4]] - c0
        xy = np.stack([p @ lateral, p @ u], axis=1)
        ax2.fill(xy[:, 0], xy[:, 1], facecolor=COLOURS[int(r)], edgecolor="k", linewidth=0.4)
    ax2.set_aspect("equal")
    ax2.set_axis_off()
    ax2.set_title("inlet cross-section")
    handles = [plt.Rectangle((0, 0), 1, 1, color=COLOURS[k]) for k in range(4)]
    ax2.legend(handles, ["lumen", "intima", "media", "adventitia"], loc="upper left", bbox_to_anchor=(0.92, 1.0))
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Renders the gallery of docs/gallery.md: real vessels from ../shared/vessels meshed with the
vesselhex Python package, each as one PNG with the vessel cut along its axis (lumen O-grid and the
three wall layers), a cross-section, and the histogram of the scaled Jacobian. Needs vesselhex,
numpy and matplotlib (headless: the Agg backend).

usage: gallery.py [--output docs/gallery] [--preset medium] [--vessels ../shared/vessels] [CASE ...]
"""
import argparse
import os
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render_mesh import COLOURS, draw_half_cut  # noqa: E402

import vesselhex  # noqa: E402

# name: (surface, centerlines or None, units, title, where the cross-section is: (polyline,
# fraction of its length), the cut view cropped to this many radii around the first junction or
# None). Every case here meshes within the quality bars today.
CASES = {
    "vmtk_aortoiliac": (
        "aorta-surface-open-ends.stl",
        "aorta-centerline.vtp",
        "mm",
        "Aorto-iliac bifurcation (VMTK test data, CT)",
        (0, 0.3),
        None,
    ),
    "gmsh_carotid_bifurcation": (
        "carotid.stl",
        "centerlinesCAROTID.vtk",
        "m",
        "Carotid bifurcation (gmsh benchmark)",
        (0, 0.12),
        5,
    ),
    "gmsh_aortic_arch": (
        "aorta.stl",
        "centerlinesAORTA.vtk",
        "m",
        "Aortic arch with three supra-aortic branches (gmsh benchmark)",
        (0, 0.2),
        None,
    ),
    "aneupy_aaa": (
        "Lumen.stl",
        None,
        "mm",
        "Abdominal aortic aneurysm (AneuPy), centerlines computed from the surface",
        (0, 0.5),
        None,
    ),
}

UNIT_MM = {"um": 1e-3, "mm": 1.0, "cm": 10.0, "m": 1000.0}
BAR = 0.2  # the worst element the bars allow (scaled Jacobian)
EDGES = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]


def station(m, line, fraction):
    """A point, tangent and radius of polyline `line` of the mesh's centerlines at `fraction` of
    its length, in the mesh's unit (the centerlines are in the input unit)."""
    points, radii = m.centerlines[line]
    scale = UNIT_MM[m.report["input"]["units"]] / UNIT_MM[m.length_unit]
    points = points * scale
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    i = int(np.searchsorted(s, fraction * s[-1]))
    i = min(max(i, 1), len(points) - 2)
    tangent = points[i + 1] - points[i - 1]
    radius = radii[i] * scale if radii is not None else s[-1] / 10
    return points[i], tangent / np.linalg.norm(tangent), radius


def cross_section(m, centre, normal, reach):
    """Polygons where the plane through `centre` normal to `normal` cuts the hexahedra within
    `reach` of the centre, in plane coordinates, with each one's region."""
    d = (m.points - centre) @ normal
    near = np.linalg.norm(m.points[m.hexes].mean(axis=1) - centre, axis=1) < reach
    dh = d[m.hexes]
    cut = near & (dh.min(axis=1) < 0) & (dh.max(axis=1) > 0)
    u = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    polygons = []
    for e in np.flatnonzero(cut):
        h = m.hexes[e]
        pts = []
        for a, b in EDGES:
            da, db = d[h[a]], d[h[b]]
            if (da < 0) != (db < 0):
                t = da / (da - db)
                pts.append(m.points[h[a]] + t * (m.points[h[b]] - m.points[h[a]]))
        p = np.asarray(pts) - centre
        xy = np.stack([p @ u, p @ v], axis=1)
        mid = xy.mean(axis=0)
        order = np.argsort(np.arctan2(xy[:, 1] - mid[1], xy[:, 0] - mid[0]))
        polygons.append((xy[order], int(m.region[e])))
    return polygons


def render(name, m, title, where, crop, out, seconds):
    fig = plt.figure(figsize=(13, 5), dpi=80)
    grid = fig.add_gridspec(1, 3, width_ratios=[1.6, 1, 1])
    ax = fig.add_subplot(grid[0], projection="3d")
    shown = np.ones(len(m.hexes), dtype=bool)
    cut_title = "cut along the vessel"
    if crop is not None and m.report["junctions"]:
        junction = m.report["junctions"][0]
        centroids = m.points[m.hexes].mean(axis=1)
        shown = np.linalg.norm(centroids - junction["centre"], axis=1) < crop * junction["radius"]
        cut_title = "cut through the junction"
    draw_half_cut(ax, m.points, m.hexes[shown], m.region[shown], title=cut_title, zoom=1.3)
    ax2 = fig.add_subplot(grid[1])
    centre, tangent, radius = station(m, *where)
    reach = 2.5 * radius  # the vessel's own section, not another part the plane cuts
    for xy, r in cross_section(m, centre, tangent, reach):
        ax2.fill(xy[:, 0], xy[:, 1], facecolor=COLOURS[r], edgecolor="k", linewidth=0.3)
    ax2.set_aspect("equal")
    ax2.set_axis_off()
    ax2.set_title(f"cross-section {int(100 * where[1])} % along the first path")
    ax3 = fig.add_subplot(grid[2])
    bins = np.linspace(0, 1, 41)
    wall = m.region > 0
    ax3.hist([m.scaled_jacobian[~wall], m.scaled_jacobian[wall]], bins=bins, stacked=True, color=[COLOURS[0], COLOURS[2]], label=["lumen", "wall"])
    ax3.axvline(BAR, color="k", linestyle="--", linewidth=1)
    ax3.set_yscale("log")
    ax3.set_xlabel("scaled Jacobian")
    ax3.set_ylabel("elements")
    ax3.legend(loc="upper left")
    r = m.report
    ax3.set_title(
        f"min {m.scaled_jacobian.min():.2f}, wall mean {r['wall']['scaled_jacobian']['mean']:.2f}, "
        f"lumen skew {r['lumen']['equiangle_skew']['mean']:.2f}",
        fontsize=10,
    )
    handles = [plt.Rectangle((0, 0), 1, 1, color=COLOURS[k]) for k in range(4)]
    fig.legend(handles, list(vesselhex.REGIONS), loc="lower center", ncol=4, frameon=False)
    fig.suptitle(f"{title}: {len(m.hexes)} hexes, {len(m.branch_names)} branch{'es' if len(m.branch_names) != 1 else ''}, {r['config']['preset']} preset, {seconds:.1f} s")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(out)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", default="docs/gallery")
    parser.add_argument("--preset", default="medium")
    default_vessels = Path(__file__).resolve().parents[1].parent / "shared" / "vessels"
    parser.add_argument("--vessels", default=os.environ.get("VESSELHEX_VESSELS", default_vessels))
    parser.add_argument("cases", nargs="*", default=list(CASES))
    args = parser.parse_args()
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    for name in args.cases:
        surface, centerlines, units, title, where, crop = CASES[name]
        folder = Path(args.vessels) / name
        start = time.perf_counter()
        m = vesselhex.mesh(
            folder / surface,
            None if centerlines is None else folder / centerlines,
            preset=args.preset,
            units=units,
        )
        seconds = time.perf_counter() - start
        path = out / f"{name}.png"
        render(name, m, title, where, crop, path, seconds)
        print(f"{path}: {len(m.hexes)} hexes, min scaled Jacobian {m.scaled_jacobian.min():.3f}, {seconds:.1f} s")


if __name__ == "__main__":
    main()

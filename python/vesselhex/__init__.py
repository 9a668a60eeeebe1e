"""Structured hexahedral meshes of blood vessels, from Python.

vesselhex turns a lumen surface (and, optionally, its centerlines) into a structured, conformal
hexahedral mesh: the lumen as an O-grid and a three-layer wall (intima, media, adventitia) that
shares its nodes, with per-element material triads, collagen fibres and quality figures. This
package runs the same Rust library as the ``vesselhex`` command and hands the mesh back as numpy
arrays::

    import vesselhex
    m = vesselhex.mesh("fixtures/aaa.stl", "fixtures/aaa_centerline.csv", preset="coarse")
    m.points, m.hexes, m.region          # (n, 3) float64, (m, 8) int64, (m,) int32
    m.report["wall"]["all"]["scaled_jacobian"]
    m.write("out/aaa", formats=["vtu", "calculix"])
    grid = m.to_pyvista()                 # or m.to_meshio()

A cohort is one call, here or on a Dask cluster: :func:`mesh_many` meshes the cases of a
manifest, each in a process of its own, and returns the results table (a pandas DataFrame).

The surface may be a file (STL, VTP, legacy VTK), ``(points, triangles)`` arrays, or a PyVista,
meshio or VTK polydata object, so a VMTK or PyVista pipeline passes it straight in. Errors are
:class:`VesselhexError` subclasses carrying the command line's one-line message. The GIL is
released while meshing and writing.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._batch import mesh_many
from ._native import ConfigError, FileError, GeometryError, InputError, VesselhexError

__all__ = [
    "mesh",
    "mesh_many",
    "centerlines",
    "formats",
    "Mesh",
    "Centerlines",
    "REGIONS",
    "VesselhexError",
    "InputError",
    "ConfigError",
    "GeometryError",
    "FileError",
]

__version__: str = _native.__version__

#: Names of the ``region`` codes: 0 lumen, 1 intima, 2 media, 3 adventitia.
REGIONS: Tuple[str, ...] = ("lumen", "intima", "media", "adventitia")

PathLike = Union[str, "os.PathLike[str]"]
#: A surface: a file, ``(points, triangles)``, or a PyVista / meshio / VTK polydata object.
SurfaceLike = Any
#: Centerlines: a file, a :class:`Centerlines`, an ``(n, 4)`` array of x, y, z, radius (or
#: ``(n, 3)`` without radius), a list of such arrays (one per polyline), or polydata with lines.
CenterlinesLike = Any
Point = Sequence[float]


def formats() -> Dict[str, str]:
    """The output formats :meth:`Mesh.write` knows, with what each writes."""
    return dict(_native.formats())


def _is_path(x: Any) -> bool:
    return isinstance(x, (str, os.PathLike))


def _triangles(offsets: np.ndarray, connectivity: np.ndarray) -> np.ndarray:
    """Triangles of polygons given as VTK offsets and connectivity; larger polygons are fanned
    (as the file readers do)."""
    offsets = np.asarray(offsets, dtype=np.int64)
    connectivity = np.asarray(connectivity, dtype=np.int64)
    sizes = np.diff(offsets)
    if np.all(sizes == 3):
        return connectivity[offsets[0] : offsets[-1]].reshape(-1, 3)
    fans = [
        (connectivity[a], connectivity[a + k], connectivity[a + k + 1])
        for a, n in zip(offsets[:-1], sizes)
        for k in range(1, n - 1)
    ]
    return np.asarray(fans, dtype=np.int64).reshape(-1, 3)


def _vtk_cells(cell_array: Any) -> Tuple[np.ndarray, np.ndarray]:
    """Offsets and connectivity of a ``vtkCellArray``."""
    from vtkmodules.util.numpy_support import vtk_to_numpy

    offsets = vtk_to_numpy(cell_array.GetOffsetsArray()).astype(np.int64)
    connectivity = vtk_to_numpy(cell_array.GetConnectivityArray()).astype(np.int64)
    return offsets, connectivity


def _surface_arrays(surface: SurfaceLike) -> Tuple[np.ndarray, np.ndarray]:
    """(points, triangles) of a surface given as arrays or as a polydata object."""
    if isinstance(surface, (tuple, list)) and len(surface) == 2:
        points, triangles = surface
    elif hasattr(surface, "GetPoints") and hasattr(surface, "GetPolys"):  # vtkPolyData: VMTK, PyVista
        from vtkmodules.util.numpy_support import vtk_to_numpy

        points = vtk_to_numpy(surface.GetPoints().GetData())
        triangles = _triangles(*_vtk_cells(surface.GetPolys()))
    elif hasattr(surface, "cells_dict") and hasattr(surface, "points"):  # meshio.Mesh
        if "triangle" not in surface.cells_dict:
            raise InputError("surface (meshio): has no triangle cells")
        points, triangles = surface.points, surface.cells_dict["triangle"]
    else:
        raise TypeError(
            "surface: give a file path, (points, triangles) arrays, or a PyVista, meshio or VTK polydata "
            f"object, not {type(surface).__name__}"
        )
    points = np.ascontiguousarray(points, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"surface (points, triangles): points must be (n, 3), not {points.shape}")
    if triangles.ndim != 2 or triangles.shape[1] != 3:
        raise InputError(f"surface (points, triangles): triangles must be (m, 3), not {triangles.shape}")
    return points, triangles


def _polyline(array: Any) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    a = np.asarray(array, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise InputError(f"centerlines (arrays): a polyline must be (n, 4) x, y, z, radius or (n, 3), not {a.shape}")
    points = np.ascontiguousarray(a[:, :3])
    radii = np.ascontiguousarray(a[:, 3]) if a.shape[1] == 4 else None
    return points, radii


_RADIUS = "MaximumInscribedSphereRadius"


def _centerline_arrays(lines: CenterlinesLike) -> List[Tuple[np.ndarray, Optional[np.ndarray]]]:
    """Polylines of centerlines given as arrays or as polydata with lines."""
    if hasattr(lines, "GetPoints") and hasattr(lines, "GetLines"):  # vtkPolyData: VMTK, PyVista
        from vtkmodules.util.numpy_support import vtk_to_numpy

        points = vtk_to_numpy(lines.GetPoints().GetData()).astype(np.float64)
        radius = lines.GetPointData().GetArray(_RADIUS)
        radii = vtk_to_numpy(radius).astype(np.float64) if radius is not None else None
        offsets, connectivity = _vtk_cells(lines.GetLines())
    else:
        a = np.asarray(lines, dtype=object if isinstance(lines, (list, tuple)) else np.float64)
        if a.dtype != object and a.ndim == 2:
            return [_polyline(a)]
        return [_polyline(line) for line in lines]
    cells = [connectivity[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
    return [
        (np.ascontiguousarray(points[c]), None if radii is None else np.ascontiguousarray(radii[c])) for c in cells
    ]


def _surface_kwargs(surface: SurfaceLike) -> Dict[str, Any]:
    if _is_path(surface):
        return {"surface_path": os.fspath(surface)}
    return {"surface_arrays": _surface_arrays(surface)}


def _point(p: Optional[Point], what: str) -> Optional[Tuple[float, float, float]]:
    if p is None:
        return None
    a = np.asarray(p, dtype=np.float64).reshape(-1)
    if a.shape != (3,):
        raise ConfigError(f"{what} must be a point x, y, z, not {p!r}")
    return (float(a[0]), float(a[1]), float(a[2]))


def _progress(progress: Union[bool, Callable[[str], Any], None]) -> Optional[Callable[[str], Any]]:
    if progress is True:
        return lambda stage: print(f"vesselhex: {stage}", file=sys.stderr, flush=True)
    if progress in (False, None):
        return None
    if not callable(progress):
        raise TypeError("progress: give True, False or a function called with each stage's name")
    return progress


class Centerlines:
    """Centerlines computed from a surface by :func:`centerlines`: one polyline from the inlet to
    every outlet, with the maximal inscribed sphere radius at each point.

    Attributes:
        polylines: one ``(n, 3)`` array of points per polyline, inlet first, in ``units``.
        radii: one ``(n,)`` array of radii per polyline, in ``units``.
        ends: the ends found, as dicts ``kind``, ``centre`` (3,), ``radius``, ``inlet``.
        notes: what the extraction repaired or decided (caps removed, triangles flipped, ...).
        units: the length unit of the surface and of these arrays.
    """

    def __init__(self, native: "_native.Centerlines") -> None:
        self._native = native
        lines = native.polylines
        self.polylines: List[np.ndarray] = [p for p, _ in lines]
        self.radii: List[np.ndarray] = [r for _, r in lines]
        self.units: str = native.units
        self.notes: List[str] = list(native.notes)
        self.ends: List[Dict[str, Any]] = [
            {"kind": kind, "centre": np.array(centre), "radius": radius, "inlet": i == native.inlet}
            for i, (kind, centre, radius) in enumerate(native.ends)
        ]

    def write(self, path: PathLike, *, branch_split: Optional[PathLike] = None) -> None:
        """Writes the VMTK-compatible ``.vtp`` (``MaximumInscribedSphereRadius``,
        ``CenterlineIds``), and with ``branch_split`` also the branch-split variant, as
        ``vesselhex centerlines --output path [--branch-split file]`` does (byte for byte)."""
        self._native.write(os.fspath(path), None if branch_split is None else os.fspath(branch_split))

    def __len__(self) -> int:
        return len(self.polylines)

    def __repr__(self) -> str:
        return f"<vesselhex.Centerlines: {len(self)} polylines, {len(self.ends)} ends, {self.units}>"


def centerlines(
    surface: SurfaceLike,
    *,
    units: Optional[str] = None,
    inlet: Optional[Point] = None,
    ends: Sequence[Point] = (),
    max_memory: Optional[int] = None,
) -> Centerlines:
    """Computes VMTK-compatible centerlines from a bare lumen surface, as ``vesselhex
    centerlines`` does: finds the ends (open boundary loops, flat caps, tagged caps), takes the
    largest as the inlet (or the end nearest ``inlet``), and traces one polyline to every other.

    Args:
        surface: a file (``.stl``, ``.vtp``, ``.vtk``), ``(points, triangles)`` arrays, or a
            PyVista, meshio or VTK polydata object.
        units: length unit of the surface and of the points given (``um``, ``mm``, ``cm``, ``m``;
            default ``mm``); the centerlines come back in it.
        inlet: a point near the inlet, instead of the largest end.
        ends: a point on each rounded (dome) cap, which has no boundary loop to find.
        max_memory: bytes a run may plan to use (files over a tenth of it are not read).

    Raises:
        VesselhexError: with the command line's message (e.g. too few ends).
    """
    native = _native.centerlines(
        **_surface_kwargs(surface),
        units=units,
        inlet=_point(inlet, "inlet"),
        ends=[_point(e, "ends") for e in ends],
        max_memory=max_memory,
    )
    return Centerlines(native)


class Mesh:
    """A meshed vessel: lumen and three-layer wall hexahedra sharing their interface nodes.

    Every array is a fresh numpy array; per-element arrays follow ``hexes``. Elements are ordered
    lumen first, then intima, media, adventitia; within a region by branch, then along it.

    Attributes:
        points: ``(n, 3)`` float64 node coordinates in ``length_unit`` (as ``mesh.vtu`` has them).
        hexes: ``(m, 8)`` int64 node indices, VTK's hexahedron corner order.
        region: ``(m,)`` int32, 0 lumen, 1 intima, 2 media, 3 adventitia (see :data:`REGIONS`).
        branch: ``(m,)`` int32 branch index (0 for an unbranched vessel; see ``branch_names``).
        sac: ``(m,)`` int32, 1 where the element lies in a saccular aneurysm's sac, else 0.
        triads: ``(m, 3, 3)`` float64: ``e_long``, ``e_circ``, ``e_rad`` of each element.
        fibres: ``(m, 2, 3)`` float64: the two collagen fibre directions (zero in the lumen).
        scaled_jacobian: ``(m,)`` float64, Verdict's definition (1 for a cube).
        equiangle_skew: ``(m,)`` float64 (0 for a cube).
        report: ``report.json`` as a dict (its ``outputs`` list is empty until written).
        node_sets: name -> sorted node indices (interface, outer wall, end sections).
        face_sets: name -> ``(k, 2)`` rows of element and canonical face (0-5).
        centerlines: ``(points (n, 3), radii (n,))`` of each polyline the mesh was built on.
        length_unit: unit of ``points`` (``output_units``).
    """

    def __init__(self, native: "_native.Mesh") -> None:
        self._native = native
        self.points: np.ndarray = native.points
        self.hexes: np.ndarray = native.hexes
        self.region: np.ndarray = native.region
        self.branch: np.ndarray = native.branch
        self.sac: np.ndarray = native.sac
        self.triads: np.ndarray = native.triads
        self.fibres: np.ndarray = native.fibres
        self.scaled_jacobian: np.ndarray = native.scaled_jacobian
        self.equiangle_skew: np.ndarray = native.equiangle_skew
        self.length_unit: str = native.length_unit
        self.branch_names: List[str] = list(native.branch_names)
        self.node_sets: Dict[str, np.ndarray] = dict(native.node_sets)
        self.face_sets: Dict[str, np.ndarray] = dict(native.face_sets)
        self.centerlines: List[Tuple[np.ndarray, Optional[np.ndarray]]] = list(native.centerlines)
        self.report: Dict[str, Any] = json.loads(native.report_json(False))

    @property
    def e_long(self) -> np.ndarray:
        """``(m, 3)`` unit vectors along the vessel, inlet to outlet."""
        return self.triads[:, 0]

    @property
    def e_circ(self) -> np.ndarray:
        """``(m, 3)`` unit vectors around the vessel (``e_circ x e_long = e_rad``)."""
        return self.triads[:, 1]

    @property
    def e_rad(self) -> np.ndarray:
        """``(m, 3)`` unit vectors from the lumen towards the adventitia."""
        return self.triads[:, 2]

    def cell_data(self) -> Dict[str, np.ndarray]:
        """The per-element arrays under the names ``mesh.vtu`` gives them."""
        return {
            "region": self.region,
            "branch": self.branch,
            "sac": self.sac,
            "scaled_jacobian": self.scaled_jacobian,
            "equiangle_skew": self.equiangle_skew,
            "e_long": self.e_long,
            "e_circ": self.e_circ,
            "e_rad": self.e_rad,
            "fibre1": self.fibres[:, 0],
            "fibre2": self.fibres[:, 1],
        }

    def write(
        self,
        folder: PathLike,
        formats: Optional[Sequence[str]] = None,
        *,
        force: bool = False,
        reproducible: bool = False,
    ) -> List[Path]:
        """Writes the mesh into ``folder`` as ``vesselhex mesh --output folder`` does: the same
        files, byte for byte, and ``report.json``.

        Args:
            folder: the output folder, replaced as a whole (written beside it and put in place in
                one rename; a folder vesselhex did not write is refused unless ``force``).
            formats: names from :func:`formats` (default: the configuration's, ``["vtu"]``).
            force: replace a folder that holds files vesselhex did not write (they are deleted).
            reproducible: zero the timings in ``report.json`` (``--reproducible``).

        Returns:
            The files written, as paths inside ``folder``.
        """
        fmts = None if formats is None else [formats] if isinstance(formats, str) else list(formats)
        written = self._native.write(os.fspath(folder), fmts, force, reproducible)
        return [Path(folder) / f for f in written]

    def to_meshio(self) -> Any:
        """The mesh as a ``meshio.Mesh`` (one hexahedron block, the cell data of ``mesh.vtu``)."""
        import meshio

        data = {name: [values] for name, values in self.cell_data().items()}
        return meshio.Mesh(self.points, [("hexahedron", self.hexes)], cell_data=data)

    def to_pyvista(self) -> Any:
        """The mesh as a ``pyvista.UnstructuredGrid`` with the cell data of ``mesh.vtu``."""
        import pyvista

        grid = pyvista.UnstructuredGrid({pyvista.CellType.HEXAHEDRON: self.hexes}, self.points)
        for name, values in self.cell_data().items():
            grid.cell_data[name] = values
        return grid

    def __repr__(self) -> str:
        counts = ", ".join(f"{np.count_nonzero(self.region == k)} {name}" for k, name in enumerate(REGIONS))
        return (
            f"<vesselhex.Mesh: {len(self.points)} nodes, {len(self.hexes)} hexes ({counts}), "
            f"{len(self.branch_names)} branch{'es' if len(self.branch_names) != 1 else ''}, {self.length_unit}>"
        )


def mesh(
    surface: SurfaceLike,
    centerlines: CenterlinesLike = None,
    *,
    preset: Optional[str] = None,
    config: Union[PathLike, Mapping[str, Any], None] = None,
    units: Optional[str] = None,
    centerline_units: Optional[str] = None,
    output_units: Optional[str] = None,
    formats: Optional[Sequence[str]] = None,
    inlet: Optional[Point] = None,
    ends: Sequence[Point] = (),
    max_memory: Optional[int] = None,
    progress: Union[bool, Callable[[str], Any]] = False,
    caps: Optional[Mapping[str, PathLike]] = None,
    inlets: Sequence[Point] = (),
) -> Mesh:
    """Meshes a vessel, as ``vesselhex mesh`` does, and returns the :class:`Mesh` in memory.

    Args:
        surface: the lumen surface: a file (``.stl``, ``.vtp``, ``.vtk``), a folder of the wall
            and its caps (as ``--surface DIR``), ``(points, triangles)`` arrays, or a PyVista,
            meshio or VTK polydata object.
        centerlines: a VMTK ``.vtp``/``.vtk`` or ``x,y,z,r`` ``.csv`` file, a :class:`Centerlines`,
            an ``(n, 4)`` array (x, y, z, radius; ``(n, 3)`` without radius) or a list of them,
            or polydata with lines; ``None`` computes them from the surface.
        preset: ``coarse``, ``medium`` or ``fine`` (default: the case file's, else coarse).
        config: a case file (TOML path) or a dict of the same keys, e.g.
            ``{"lumen": {"radial_elements": 6}, "wall": {"thickness_mm": 0.5}}``.
        units: unit of the inputs (``um``, ``mm``, ``cm``, ``m``; default mm).
        centerline_units: unit of the centerlines when it differs from ``units``.
        output_units: unit of ``points`` and of the written files (default mm).
        formats: the formats :meth:`Mesh.write` writes by default.
        inlet: without centerlines, a point near the inlet (default: the largest end).
        ends: without centerlines, a point on each rounded cap.
        max_memory: bytes the run may plan to use (default three quarters of the machine's).
        progress: ``True`` prints each stage on stderr; a function is called with each stage's name.
        caps: with a wall file as ``surface``, its caps in files of their own, by name, e.g.
            ``{"inlet": "inlet.stl", "outlet_lica": "lica.stl"}`` (as ``--cap NAME=FILE``): each
            names the end it closes (OpenFOAM patch, sets, ``report["ends"]``); caps named
            ``inlet_<x>`` are inlets.
        inlets: points near further ends that are inlets (a vessel fed through several ends,
            as ``--inlet`` given more than once): each its own inlet, ``inlet_1``, ``inlet_2``, ...

    Raises:
        VesselhexError: ``InputError``, ``ConfigError``, ``GeometryError`` or ``FileError``, with
            the message the command line prints.
    """
    kwargs: Dict[str, Any] = _surface_kwargs(surface)
    if centerlines is None:
        pass
    elif _is_path(centerlines):
        kwargs["centerlines_path"] = os.fspath(centerlines)
    elif isinstance(centerlines, Centerlines):
        kwargs["centerlines_computed"] = centerlines._native
    else:
        kwargs["centerline_arrays"] = _centerline_arrays(centerlines)
    if config is None:
        pass
    elif _is_path(config):
        kwargs["config_path"] = os.fspath(config)
    elif isinstance(config, Mapping):
        kwargs["config_dict"] = dict(config)
    else:
        raise TypeError(f"config: give a case file path or a dict, not {type(config).__name__}")
    if isinstance(formats, str):
        formats = [formats]
    native = _native.mesh(
        **kwargs,
        preset=preset,
        units=units,
        centerline_units=centerline_units,
        output_units=output_units,
        formats=None if formats is None else list(formats),
        inlet=_point(inlet, "inlet"),
        ends=[_point(e, "ends") for e in ends],
        max_memory=max_memory,
        progress=_progress(progress),
        caps=[(str(name), os.fspath(file)) for name, file in (caps or {}).items()],
        inlets=[_point(p, "inlets") for p in inlets],
    )
    return Mesh(native)

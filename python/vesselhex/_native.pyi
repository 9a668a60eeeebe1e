"""Type stubs of the extension module (see vesselhex/__init__.py for the documented API)."""

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

__version__: str

class VesselhexError(Exception): ...
class InputError(VesselhexError): ...
class ConfigError(VesselhexError): ...
class GeometryError(VesselhexError): ...
class FileError(VesselhexError): ...

Polyline = Tuple[npt.NDArray[np.float64], Optional[npt.NDArray[np.float64]]]
Point = Tuple[float, float, float]

class Mesh:
    points: npt.NDArray[np.float64]
    hexes: npt.NDArray[np.int64]
    region: npt.NDArray[np.int32]
    branch: npt.NDArray[np.int32]
    sac: npt.NDArray[np.int32]
    scaled_jacobian: npt.NDArray[np.float64]
    equiangle_skew: npt.NDArray[np.float64]
    triads: npt.NDArray[np.float64]
    fibres: npt.NDArray[np.float64]
    length_unit: str
    branch_names: List[str]
    node_sets: Dict[str, npt.NDArray[np.int64]]
    face_sets: Dict[str, npt.NDArray[np.int64]]
    centerlines: List[Polyline]
    def report_json(self, reproducible: bool) -> str: ...
    def write(
        self, folder: str, formats: Optional[List[str]] = None, force: bool = False, reproducible: bool = False
    ) -> List[str]: ...

class Centerlines:
    polylines: List[Polyline]
    units: str
    ends: List[Tuple[str, Point, float]]
    inlet: int
    notes: List[str]
    def write(self, path: str, branch_split: Optional[str] = None) -> None: ...

def mesh(
    *,
    surface_path: Optional[str] = None,
    surface_arrays: Optional[Tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]] = None,
    centerlines_path: Optional[str] = None,
    centerline_arrays: Optional[List[Polyline]] = None,
    centerlines_computed: Optional[Centerlines] = None,
    preset: Optional[str] = None,
    config_path: Optional[str] = None,
    config_dict: Optional[Dict[str, Any]] = None,
    units: Optional[str] = None,
    centerline_units: Optional[str] = None,
    output_units: Optional[str] = None,
    formats: Optional[List[str]] = None,
    inlet: Optional[Point] = None,
    ends: Sequence[Point] = ...,
    max_memory: Optional[int] = None,
    progress: Optional[Callable[[str], Any]] = None,
    caps: Sequence[Tuple[str, str]] = ...,
    inlets: Sequence[Point] = ...,
) -> Mesh: ...
def centerlines(
    *,
    surface_path: Optional[str] = None,
    surface_arrays: Optional[Tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]] = None,
    units: Optional[str] = None,
    inlet: Optional[Point] = None,
    ends: Sequence[Point] = ...,
    max_memory: Optional[int] = None,
) -> Centerlines: ...
def formats() -> List[Tuple[str, str]]: ...
def batch_cases(*, manifest: Optional[str] = None, rows: Optional[str] = None, base: Optional[str] = None) -> str: ...

class Batch:
    def __init__(self, cases: str, settings: str, output: str) -> None: ...
    def pending(self) -> List[Tuple[str, str, Optional[str]]]: ...
    def finish(self, ran: str) -> str: ...
    def run_local(
        self, jobs: int, program: str, args: List[str], event: Optional[Callable[[str, str], Any]]
    ) -> Tuple[str, str]: ...

def batch_run_case(job: str, fingerprint: Optional[str], program: str, args: List[str]) -> str: ...
def batch_failed_row(case: str, cause: str) -> str: ...
def batch_child() -> int: ...

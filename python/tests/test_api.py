"""The Python API against the command line: the same meshes, files and errors."""

import filecmp
import json
import threading
from pathlib import Path

import numpy as np
import pytest

import vesselhex
from conftest import require, run_cli

AAA = ("fixtures/aaa.stl", "fixtures/aaa_centerline.csv")
Y = ("fixtures/y_bifurcation.stl", "fixtures/y_bifurcation_centerlines.vtp")


def read_vtu(path: Path):
    return require("meshio").read(path)


def same_files(a: Path, b: Path) -> list:
    """Relative paths of the files that differ or exist on one side only (recursively)."""
    cmp = filecmp.dircmp(a, b)
    out = [str(Path(cmp.left).relative_to(a) / f) for f in cmp.left_only + cmp.right_only + cmp.funny_files]
    out += [str(Path(cmp.left).relative_to(a) / f) for f in filecmp.cmpfiles(a, b, cmp.common_files, shallow=False)[1]]
    for sub in cmp.common_dirs:
        out += [str(Path(sub) / f) for f in same_files(a / sub, b / sub)]
    return out


def assert_arrays_equal_vtu(m: vesselhex.Mesh, vtu: Path) -> None:
    """Every array of the mesh equals the one in the command line's mesh.vtu, bit for bit."""
    grid = read_vtu(vtu)
    assert np.array_equal(m.points, grid.points)
    assert np.array_equal(m.hexes, grid.cells_dict["hexahedron"])
    data = {k: v["hexahedron"] for k, v in grid.cell_data_dict.items()}
    assert sorted(data) == sorted(m.cell_data())
    for name, values in m.cell_data().items():
        assert values.dtype == data[name].dtype, name
        assert np.array_equal(values, data[name]), name


def test_aaa_arrays_equal_the_command_lines_vtu(repo, cli, tmp_path):
    surface, centerline = (repo / p for p in AAA)
    run_cli(cli, "mesh", "--surface", surface, "--centerlines", centerline, "--output", tmp_path / "cli", "--quiet")
    m = vesselhex.mesh(surface, centerline)
    assert_arrays_equal_vtu(m, tmp_path / "cli" / "mesh.vtu")
    # What the arrays say is what the report says, and the elements are valid.
    assert len(m.hexes) == m.report["elements"] and len(m.points) == m.report["nodes"]
    assert m.scaled_jacobian.min() > 0 and m.report["lumen"]["scaled_jacobian"]["min"] > 0
    assert [int(np.count_nonzero(m.region == k)) for k in range(4)] == [
        m.report["lumen"]["elements"],
        *[layer["elements"] for layer in m.report["wall"]["layers"]],
    ]
    # Triads are orthonormal and right-handed (e_circ x e_long = e_rad); fibres unit in the wall.
    e_long, e_circ, e_rad = m.e_long, m.e_circ, m.e_rad
    assert np.allclose(np.cross(e_circ, e_long), e_rad, atol=1e-9)
    wall = m.region > 0
    assert np.allclose(np.linalg.norm(m.fibres[wall], axis=2), 1.0) and not m.fibres[~wall].any()


def test_write_is_byte_identical_to_the_command_line_in_every_format(repo, cli, tmp_path):
    """The branched Y in every format, in cm with binary OpenFOAM files: the same files, report.json
    included (timings zeroed), as `vesselhex mesh` writes."""
    surface, centerlines = (repo / p for p in Y)
    formats = [name for name in vesselhex.formats()]
    case = tmp_path / "case.toml"
    case.write_text('output_units = "cm"\n[openfoam]\nbinary = true\n[lumen]\nradial_elements = 3\n')
    args = ["--surface", surface, "--centerlines", centerlines, "--config", case, "--reproducible", "--quiet"]
    run_cli(cli, "mesh", *args, "--formats", ",".join(formats), "--output", tmp_path / "cli")
    m = vesselhex.mesh(surface, centerlines, config=case)
    written = m.write(tmp_path / "py", formats=formats, reproducible=True)
    assert same_files(tmp_path / "cli", tmp_path / "py") == []
    report = json.loads((tmp_path / "py" / "report.json").read_text())
    assert sorted(str(p.relative_to(tmp_path / "py")) for p in written) == sorted(report["outputs"])
    assert report["length_unit"] == "cm" and m.length_unit == "cm"
    assert len(m.branch_names) == 3 and set(np.unique(m.branch)) == {0, 1, 2}


def test_config_as_a_dict_is_the_case_file(repo, tmp_path):
    surface, centerline = (repo / p for p in AAA)
    case = tmp_path / "case.toml"
    case.write_text('preset = "medium"\n[lumen]\nradial_elements = 5\n[wall]\nthickness_mm = 1.5\n')
    from_file = vesselhex.mesh(surface, centerline, config=case)
    from_dict = vesselhex.mesh(
        surface, centerline, config={"preset": "medium", "lumen": {"radial_elements": 5}, "wall": {"thickness_mm": 1.5}}
    )
    assert from_file.report["config"] == from_dict.report["config"]
    assert from_dict.report["config"]["lumen"]["radial_elements"] == 5
    assert np.array_equal(from_file.points, from_dict.points)
    # preset= overrides the file's, as --preset does; units= as --units.
    coarse = vesselhex.mesh(surface, centerline, config=case, preset="coarse")
    assert coarse.report["config"]["preset"] == "coarse" and len(coarse.hexes) < len(from_file.hexes)


def test_surface_and_centerline_as_arrays(repo):
    """A pipeline's arrays give the mesh the files give: the STL's triangles as (points,
    triangles) (read by meshio, whose vertex order differs), the CSV as an (n, 4) array."""
    meshio = require("meshio")
    surface, centerline = (repo / p for p in AAA)
    from_files = vesselhex.mesh(surface, centerline)
    stl = meshio.read(surface)
    table = np.loadtxt(centerline, delimiter=",", skiprows=1)
    from_arrays = vesselhex.mesh((stl.points, stl.cells_dict["triangle"]), table)
    assert np.array_equal(from_files.hexes, from_arrays.hexes)
    assert np.allclose(from_files.points, from_arrays.points, rtol=0, atol=1e-9)
    assert from_arrays.report["input"]["surface"] == "surface (points, triangles)"
    # The meshio object itself, and the centerline as a list of polylines, work alike.
    again = vesselhex.mesh(stl, [table])
    assert np.array_equal(again.points, from_arrays.points)
    # Units apply to arrays as to files: the same vessel in metres, within 10 nm (the conversion
    # rounds, and the iterations it feeds converge within their own tolerance: 1.03 nm measured).
    in_m = vesselhex.mesh((stl.points / 1000, stl.cells_dict["triangle"]), table / 1000, units="m")
    assert np.array_equal(in_m.hexes, from_arrays.hexes)
    assert np.allclose(in_m.points, from_arrays.points, rtol=0, atol=1e-5)


def test_pyvista_and_vtk_objects_pass_straight_in(repo):
    """PyVista's polydata and a bare vtkPolyData (what VMTK's scripts hand over) give the mesh the
    files give."""
    pv = require("pyvista")
    from vtkmodules.vtkIOGeometry import vtkSTLReader
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    surface, centerlines = (repo / p for p in Y)
    from_files = vesselhex.mesh(surface, centerlines)
    from_pyvista = vesselhex.mesh(pv.read(surface), pv.read(centerlines))
    readers = []
    for reader, path in ((vtkSTLReader(), surface), (vtkXMLPolyDataReader(), centerlines)):
        reader.SetFileName(str(path))
        reader.Update()
        readers.append(reader.GetOutput())
    from_vtk = vesselhex.mesh(*readers)
    for m in (from_pyvista, from_vtk):
        assert np.array_equal(m.hexes, from_files.hexes)
        assert np.allclose(m.points, from_files.points, rtol=0, atol=1e-9)


def test_to_meshio_and_to_pyvista(repo, tmp_path):
    m = vesselhex.mesh(*(repo / p for p in Y))
    meshio = require("meshio")
    mm = m.to_meshio()
    mm.write(tmp_path / "y.vtu")
    back = meshio.read(tmp_path / "y.vtu")
    assert np.array_equal(back.cells_dict["hexahedron"], m.hexes)
    assert np.array_equal(back.cell_data_dict["region"]["hexahedron"], m.region)
    pv = require("pyvista")
    grid = m.to_pyvista()
    assert grid.n_cells == len(m.hexes) and grid.n_points == len(m.points)
    # Every hexahedron has a positive volume in VTK's own measure (the corner order is VTK's).
    volumes = grid.compute_cell_sizes(length=False, area=False, volume=True).cell_data["Volume"]
    assert volumes.min() > 0
    # A cut across the parent vessel shows lumen and all three layers.
    cut = grid.slice(normal="z", origin=grid.center)
    assert set(np.unique(cut.cell_data["region"])) == {0, 1, 2, 3}


def test_centerlines_equal_the_command_lines_and_mesh_alike(repo, cli, tmp_path):
    surface = repo / Y[0]
    run_cli(cli, "centerlines", "--surface", surface, "--output", tmp_path / "cli.vtp", "--quiet")
    cl = vesselhex.centerlines(surface)
    cl.write(tmp_path / "py.vtp")
    assert (tmp_path / "cli.vtp").read_bytes() == (tmp_path / "py.vtp").read_bytes()
    assert len(cl) == 2 and sum(e["inlet"] for e in cl.ends) == 1 and len(cl.ends) == 3
    assert all(r.min() > 0 and len(r) == len(p) for p, r in zip(cl.polylines, cl.radii))
    # Meshing with them is meshing the bare surface (which computes the same centerlines).
    bare = vesselhex.mesh(surface)
    given = vesselhex.mesh(surface, cl)
    assert np.array_equal(bare.points, given.points) and np.array_equal(bare.hexes, given.hexes)
    assert bare.report["input"]["centerlines"] == "(computed from the surface)"


def test_errors_carry_the_command_lines_message(repo, cli, tmp_path):
    surface, centerline = (repo / p for p in AAA)
    bad_case = tmp_path / "bad.toml"
    bad_case.write_text("[lumen]\nradial_elements = 0\n")
    cases = [
        ((tmp_path / "missing.stl",), {}, ["--surface", tmp_path / "missing.stl"], vesselhex.FileError),
        ((surface, centerline), {"config": bad_case}, ["--surface", surface, "--centerlines", centerline, "--config", bad_case], vesselhex.InputError),
        # The centerline read in metres lies far outside the surface in mm.
        ((surface, centerline), {"centerline_units": "m"}, ["--surface", surface, "--centerlines", centerline, "--centerline-units", "m"], vesselhex.InputError),
    ]
    for args, kwargs, cli_args, kind in cases:
        done = run_cli(cli, "mesh", *cli_args, "--output", tmp_path / "out", "--quiet", check=False)
        assert done.returncode == 1
        line = done.stderr.strip().splitlines()[-1]
        assert line.startswith("vesselhex: error: ")
        with pytest.raises(kind) as raised:
            vesselhex.mesh(*args, **kwargs)
        assert str(raised.value) == line[len("vesselhex: error: ") :]
        assert isinstance(raised.value, vesselhex.VesselhexError)
    with pytest.raises(vesselhex.ConfigError, match="unknown preset 'finest'"):
        vesselhex.mesh(surface, centerline, preset="finest")
    with pytest.raises(vesselhex.InputError, match="triangle 0 is \\[0, 1, 7\\]"):
        vesselhex.mesh((np.zeros((3, 3)), np.array([[0, 1, 7]])), centerline)
    with pytest.raises(vesselhex.ConfigError, match="unknown format 'stl'"):
        vesselhex.mesh(surface, centerline).write(tmp_path / "out", formats=["stl"])


def test_write_keeps_the_output_protocol(repo, tmp_path):
    """A folder holding someone else's file is refused (nothing changed), replaced with force."""
    m = vesselhex.mesh(*(repo / p for p in AAA))
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(vesselhex.VesselhexError, match="--force"):
        m.write(out)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert [p.name for p in m.write(out, force=True)] == ["mesh.vtu", "report.json"]
    assert sorted(p.name for p in out.iterdir()) == ["mesh.vtu", "report.json"]
    # A folder vesselhex wrote is replaced without force; formats the new run lacks go.
    m.write(out, formats=["calculix"])
    assert sorted(p.name for p in out.iterdir()) == ["calculix", "report.json"]


def test_progress_and_the_gil(repo):
    """Stages are reported in order, and other Python threads run while the mesher works (the
    GIL is released): a counter in this thread advances between two stages."""
    surface, centerlines = (repo / p for p in Y)
    counter = {"n": 0, "done": False}
    seen = []

    def stage(name):
        seen.append((name, counter["n"]))

    def work():
        try:
            vesselhex.mesh(surface, centerlines, preset="medium", progress=stage)
        finally:
            counter["done"] = True

    worker = threading.Thread(target=work)
    worker.start()
    while not counter["done"]:
        counter["n"] += 1
    worker.join()
    names = [n for n, _ in seen]
    assert names == ["reading", "surface hygiene", "surface index", "centerline", "projection", "volume", "annotation", "surface accuracy"]
    at = dict(seen)
    assert at["annotation"] - at["projection"] > 1000, seen
    # A callback that raises stops nothing half-way and its exception comes back.
    def fails(name):
        raise RuntimeError(f"stop at {name}")

    with pytest.raises(RuntimeError, match="stop at reading"):
        vesselhex.mesh(surface, centerlines, progress=fails)


def test_a_real_vessel_equals_the_command_line(cli, vessels, tmp_path):
    """vmtk_aortoiliac (CT, mm, capped ends open) with VMTK's centerlines, at coarse: arrays equal
    mesh.vtu, three branches, every element valid."""
    case = vessels / "vmtk_aortoiliac"
    surface, centerlines = case / "aorta-surface-open-ends.stl", case / "aorta-centerline.vtp"
    run_cli(cli, "mesh", "--surface", surface, "--centerlines", centerlines, "--output", tmp_path / "cli", "--quiet")
    m = vesselhex.mesh(surface, centerlines)
    assert_arrays_equal_vtu(m, tmp_path / "cli" / "mesh.vtu")
    assert len(m.branch_names) == 3 and m.scaled_jacobian.min() > 0
    assert m.report["within_bars"]


def test_further_inlets_are_the_command_lines(repo, cli, tmp_path):
    """A daughter of the Y flagged as a second inlet (``inlets=``, as ``--inlet`` with the
    centerlines given): the same files as the command line writes, the daughter's end an inlet
    named ``inlet_2`` beside the trunk's ``inlet_1``, each its own OpenFOAM patch."""
    surface, centerlines = (repo / p for p in Y)
    ends = vesselhex.mesh(surface, centerlines).report["ends"]
    daughter = next(e["position"] for e in ends if not e["inlet"])
    args = ["--surface", surface, "--centerlines", centerlines, "--reproducible", "--quiet", "--formats", "vtu,openfoam"]
    run_cli(cli, "mesh", *args, "--inlet=" + ",".join(map(repr, daughter)), "--output", tmp_path / "cli")
    m = vesselhex.mesh(surface, centerlines, inlets=[daughter])
    m.write(tmp_path / "py", formats=["vtu", "openfoam"], reproducible=True)
    assert same_files(tmp_path / "cli", tmp_path / "py") == []
    inlets = sorted(e["name"] for e in m.report["ends"] if e["inlet"])
    assert inlets == ["inlet_1", "inlet_2"]
    boundary = (tmp_path / "py" / "openfoam" / "constant" / "polyMesh" / "boundary").read_text()
    assert all(f"    {name}\n" in boundary for name in inlets)

"""mesh_many against the command line's batch: the same table and the same meshes, on a Dask
LocalCluster and in local processes. Under CI a missing dask.distributed or pandas is a failure."""

import json
import math
import sys
from pathlib import Path

import pytest

import vesselhex
from conftest import require, run_cli

#: Columns that are measured, not computed: they differ from run to run and between the command's
#: processes and the interpreter's.
MEASURED = ("seconds", "peak_memory_mib")


def same_value(a, b) -> bool:
    """Equal, a missing value being None in JSON and NaN in a DataFrame."""
    missing = lambda v: v is None or (isinstance(v, float) and math.isnan(v))
    return (missing(a) and missing(b)) or a == b


def test_mesh_many_on_a_dask_cluster_gives_the_command_lines_table_and_meshes(cli, vessels, tmp_path):
    distributed = require("distributed")
    pandas = require("pandas")
    manifest = vessels / "manifest.json"
    run_cli(cli, "batch", manifest, "--output", tmp_path / "cli", "--jobs", "2", "--preset", "coarse", "--quiet")
    expected = json.loads((tmp_path / "cli" / "summary.json").read_text())
    assert len(expected) == 18
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            table = vesselhex.mesh_many(manifest, tmp_path / "dask", client=client, preset="coarse")
            # Done: a rerun on the cluster skips every case.
            again = vesselhex.mesh_many(manifest, tmp_path / "dask", client=client, preset="coarse")
    assert isinstance(table, pandas.DataFrame)
    assert list(table.columns) == list(expected[0])
    rows = table.to_dict(orient="records")
    assert [r["case"] for r in rows] == [r["case"] for r in expected]
    for got, want in zip(rows, expected):
        assert got["status"] == "meshed" and got["exit"] == 0, got
        for column in want:
            if column not in MEASURED:
                assert same_value(got[column], want[column]), f"{want['case']}: {column} {got[column]} != {want[column]}"
        assert got["peak_memory_mib"] > 1 and got["seconds"] > 0
        mine, theirs = (tmp_path / d / want["case"] / "mesh.vtu" for d in ("dask", "cli"))
        assert mine.read_bytes() == theirs.read_bytes(), f"{want['case']}: mesh.vtu differs from the command's"
    # The summary files are the table.
    written = json.loads((tmp_path / "dask" / "summary.json").read_text())
    assert [r["case"] for r in written] == list(table["case"]) and (tmp_path / "dask" / "summary.csv").is_file()
    assert list(again["status"]) == ["skipped"] * 18
    assert list(again["hexes"]) == list(table["hexes"])


def test_mesh_many_here_takes_rows_and_fails_a_broken_one_alone(repo, tmp_path, monkeypatch):
    cases = [
        {"case": "broken", "surface": str(tmp_path / "nowhere.stl")},
        {"case": "aaa", "surface": repo / "fixtures/aaa.stl", "centerlines": repo / "fixtures/aaa_centerline.csv"},
    ]
    table = vesselhex.mesh_many(cases, tmp_path / "out", jobs=2, config={"lumen": {"radial_elements": 3}})
    rows = table if isinstance(table, list) else table.to_dict(orient="records")
    broken, aaa = rows
    assert (broken["case"], broken["status"], broken["exit"]) == ("broken", "failed", 1)
    assert "nowhere.stl" in broken["cause"]
    assert (aaa["status"], aaa["exit"], aaa["ends_found"], aaa["ends_meshed"]) == ("meshed", 0, 2, 2)
    report = json.loads((tmp_path / "out" / "aaa" / "report.json").read_text())
    assert report["config"]["lumen"]["radial_elements"] == 3 and aaa["hexes"] == report["elements"]
    # Without pandas: a list of dicts of the same columns.
    monkeypatch.setitem(sys.modules, "pandas", None)
    again = vesselhex.mesh_many(cases, tmp_path / "out", jobs=2, config={"lumen": {"radial_elements": 3}})
    assert isinstance(again, list) and list(again[1]) == list(rows[1])
    assert [r["status"] for r in again] == ["failed", "skipped"]


def test_bad_cases_are_refused_before_anything_is_meshed(tmp_path):
    with pytest.raises(vesselhex.InputError, match="'colour' is not a setting"):
        vesselhex.mesh_many([{"surface": "a.stl", "colour": "red"}], tmp_path / "out")
    with pytest.raises(TypeError, match="a manifest file, a DataFrame or dicts"):
        vesselhex.mesh_many(["a.stl"], tmp_path / "out")
    assert not (tmp_path / "out").exists()

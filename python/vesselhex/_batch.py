"""Cohorts: :func:`mesh_many` meshes many vessels, here or on a Dask cluster, with a results table.

Everything but the scheduling is the command line's ``vesselhex batch`` (the same Rust code): the
manifest's rows, the fingerprints that let a rerun skip what is done, each case meshed in a
process of its own (``python -m vesselhex._case``) and measured there, the summary rows and
files."""

from __future__ import annotations

import json
import os
import sys
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Union

from . import _native

PathLike = Union[str, "os.PathLike[str]"]

#: The program each case runs in: this interpreter, with the package's case runner.
_CHILD_ARGS = ["-m", "vesselhex._case"]


def _cases_json(cases: Any) -> str:
    """The cases as the Rust side takes them: a manifest file, or rows (dicts, a DataFrame)."""
    if isinstance(cases, (str, os.PathLike)):
        # Absolute, so that a cluster's workers, wherever they run, find the same files.
        return _native.batch_cases(manifest=os.path.abspath(os.fspath(cases)))
    if hasattr(cases, "to_dict") and hasattr(cases, "columns"):  # a pandas DataFrame
        cases = cases.to_dict(orient="records")
    rows = []
    for row in cases:
        if not isinstance(row, Mapping):
            raise TypeError(f"cases: give a manifest file, a DataFrame or dicts, not a list of {type(row).__name__}")
        # A DataFrame's empty cells are NaN: unset, as an empty CSV field is.
        clean = {k: (os.fspath(v) if isinstance(v, os.PathLike) else v) for k, v in row.items() if not _missing(v)}
        rows.append(clean)
    return _native.batch_cases(rows=json.dumps(rows), base=os.getcwd())


def _missing(value: Any) -> bool:
    return value is None or (isinstance(value, float) and value != value)


def _settings_json(
    *,
    force: bool,
    preset: Optional[str],
    config: Union[PathLike, Mapping[str, Any], None],
    units: Optional[str],
    output_units: Optional[str],
    formats: Union[str, Sequence[str], None],
    max_memory: Optional[int],
    reproducible: bool,
    threads: Optional[int],
) -> str:
    if isinstance(formats, str):
        formats = [formats]
    settings: Dict[str, Any] = {
        "preset": preset,
        "units": units,
        "output_units": output_units,
        "formats": None if formats is None else list(formats),
        "max_memory": max_memory,
        "reproducible": bool(reproducible),
        "threads": threads,
        "force": bool(force),
        "config": None,
        "config_table": None,
    }
    if isinstance(config, (str, os.PathLike)):
        settings["config"] = os.path.abspath(os.fspath(config))
    elif isinstance(config, Mapping):
        settings["config_table"] = dict(config)
    elif config is not None:
        raise TypeError(f"config: give a case file path or a dict, not {type(config).__name__}")
    return json.dumps(settings)


def _mesh_one(job: str, fingerprint: Optional[str]) -> Dict[str, Any]:
    """A Dask task: meshes one case (its folder written by a process of its own on this worker)
    and returns only its summary row."""
    job_settings = json.loads(job)
    if job_settings["settings"].get("threads") is None:
        # The worker's cores shared among the tasks it runs at once.
        try:
            from distributed import get_worker

            share = max(1, (os.cpu_count() or 1) // max(1, get_worker().state.nthreads))
        except Exception:
            share = None
        job_settings["settings"]["threads"] = share
        job = json.dumps(job_settings)
    return json.loads(_native.batch_run_case(job, fingerprint, sys.executable, _CHILD_ARGS))


def _on_cluster(batch: "_native.Batch", client: Any, say: Callable[[str], None]) -> str:
    """Runs the pending cases as Dask tasks on `client`'s cluster; returns every row as JSON."""
    from distributed import as_completed

    pending = batch.pending()
    futures = {
        client.submit(_mesh_one, job, fingerprint, pure=False, key=f"vesselhex-case-{name}-{os.urandom(4).hex()}"): name
        for name, job, fingerprint in pending
    }
    ran: List[Dict[str, Any]] = []
    for done, future in enumerate(as_completed(futures), start=1):
        name = futures[future]
        try:
            row = future.result()
        except Exception as e:  # the task itself failed (its worker died): the case failed
            row = json.loads(_native.batch_failed_row(name, f"its task failed on the cluster: {type(e).__name__}: {e}"))
        ran.append(row)
        say(f"case {name} {row['status']} ({done}/{len(futures)})")
    return batch.finish(json.dumps(ran))


def mesh_many(
    cases: Any,
    output_dir: PathLike,
    client: Any = None,
    *,
    jobs: Optional[int] = None,
    force: bool = False,
    preset: Optional[str] = None,
    config: Union[PathLike, Mapping[str, Any], None] = None,
    units: Optional[str] = None,
    output_units: Optional[str] = None,
    formats: Union[str, Sequence[str], None] = None,
    max_memory: Optional[int] = None,
    reproducible: bool = False,
    threads: Optional[int] = None,
    progress: bool = False,
) -> Any:
    """Meshes many vessels, as ``vesselhex batch`` does, and returns the summary table.

    Each case is meshed into ``output_dir/<case>/`` (the files ``vesselhex mesh`` writes for it
    alone, byte for byte) by a process of its own, so a crash or an out-of-memory in one case
    ends that case only; a case that fails is a row with its cause. ``output_dir/summary.csv``
    and ``summary.json`` hold the table. A rerun skips the cases meshed before from the same input
    files and settings, unless ``force``.

    Args:
        cases: a manifest (CSV or JSON file, as ``vesselhex batch`` reads), or rows: a pandas
            DataFrame or dicts with the manifest's keys (``case``, ``surface``, ``centerlines``,
            ``units``, ``config``, ``preset``, ``formats``, ...); relative paths are taken from the
            manifest's folder, or for rows from the current folder.
        output_dir: the batch's folder: one folder per case, and the summary.
        client: a ``dask.distributed.Client``: each case becomes a task on its cluster (the
            folder must be one the workers share); only the summary row comes back. ``None``:
            processes on this machine, ``jobs`` at a time.
        jobs: without a client, cases at once (default: the cores); fewer when ``max_memory``
            per case does not fit that many in the memory available.
        force: mesh every case again, replacing its folder even if it holds files vesselhex did
            not write.
        preset, config, units, output_units, formats: the settings of the cases whose rows set
            none (``config``: a case file, or a dict of its keys).
        max_memory: bytes each case may plan to use; a case estimated to need more is refused
            before it is built (default here: the memory available, shared among the jobs; on a
            cluster, three quarters of the worker's machine).
        reproducible: zero the timings in every ``report.json``.
        threads: worker threads of each case's process (default: the cores shared among the jobs).
        progress: print each case as it ends, and the memory plan, on stderr.

    Returns:
        A pandas DataFrame with the columns of ``summary.csv`` (a list of dicts when pandas is not
        installed); without a client, its ``attrs["memory"]`` says how the jobs were planned.

    Raises:
        VesselhexError: the manifest or the output folder cannot be used (nothing is meshed).
    """
    say: Callable[[str], None] = (lambda line: print(f"vesselhex: {line}", file=sys.stderr, flush=True)) if progress else (lambda line: None)
    settings = _settings_json(
        force=force,
        preset=preset,
        config=config,
        units=units,
        output_units=output_units,
        formats=formats,
        max_memory=max_memory,
        reproducible=reproducible,
        threads=threads,
    )
    cases_json = _cases_json(cases)
    batch = _native.Batch(cases_json, settings, os.path.abspath(os.fspath(output_dir)))
    memory = None
    if client is None:
        counted = {"done": 0, "of": len(json.loads(cases_json))}

        def event(kind: str, what: str) -> None:
            if kind == "plan":
                say(what)
            elif kind == "finished":
                counted["done"] += 1
                say(f"case {what} done ({counted['done']}/{counted['of']})")

        rows, memory = batch.run_local(jobs or os.cpu_count() or 1, sys.executable, _CHILD_ARGS, event)
    else:
        rows = _on_cluster(batch, client, say)
    return _table(json.loads(rows), memory)


def _table(rows: List[Dict[str, Any]], memory: Optional[str]) -> Any:
    try:
        import pandas
    except ImportError:
        return rows
    table = pandas.DataFrame(rows)
    if memory is not None:
        table.attrs["memory"] = memory
    return table

"""Every command and script the README and docs/ show is run here, one test per block.

- ``sh`` blocks run in bash from the repository's root, with this Python's environment and
  ``target/release`` first on PATH; ``cargo run --release --`` runs the command built there.
  Lines CI runs itself (building the command, the test suites, the wheel's build and install)
  are not run again: each must stand verbatim in ``.ci/run`` or, for pytest, in
  ``tests/python.rs``, which run it.
- ``python`` blocks run with this interpreter from the repository's root.
- ``toml`` blocks are case files: a fixture is meshed with each.

Slow settings are made quick: ``--preset medium``/``fine`` and ``preset="medium"`` become coarse,
and pictures meant for docs/ are drawn into a temporary folder instead."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO, require

DOCS = [REPO / "README.md", REPO / "python" / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
FENCE = re.compile(r"^```(\w+)\n(.*?)^```", re.S | re.M)
RUN = ("sh", "python", "toml")
# Shown in the docs, run by .ci/run itself (or by cargo test: tests/python.rs runs pytest).
BY_CI = ("cargo build", "cargo test", "python3 -m pytest", "pip install", "(cd python && maturin")


def blocks():
    for path in DOCS:
        text = path.read_text()
        for fence in FENCE.finditer(text):
            lang, body = fence.group(1), fence.group(2)
            if lang in RUN:
                line = text[: fence.start()].count("\n") + 1
                yield pytest.param(lang, body, id=f"{path.relative_to(REPO)}:{line}")


def quick(text: str, tmp: Path) -> str:
    text = re.sub(r"--preset (medium|fine)\b", "--preset coarse", text)
    text = re.sub(r"preset=\"(medium|fine)\"", 'preset="coarse"', text)
    return re.sub(r"(?<![\w/.])docs/(gallery\b|[\w/-]+\.png\b)", lambda m: str(tmp / m.group(1)), text)


def commands(script: str):
    """The script's commands, a backslash-continued command as one line."""
    return [c.strip() for c in script.replace("\\\n", " ").splitlines() if c.strip() and not c.lstrip().startswith("#")]


def environment(cli: Path) -> dict:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), str(cli.parent), env["PATH"]])
    return env


CARGO = """cargo() {
  if [ "${1:-} ${2:-} ${3:-}" = "run --release --" ]; then shift 3; vesselhex "$@"; else command cargo "$@"; fi
}
"""


@pytest.mark.parametrize("lang,body", list(blocks()))
def test_documented_block_runs(lang, body, cli, tmp_path):
    # what the block uses beyond vesselhex and numpy: a skip outside CI, a failure under it
    for module, used in (("pyvista", "pyvista" in body or "to_pyvista" in body), ("meshio", "meshio" in body or "render_mesh" in body),
                         ("matplotlib", "gallery.py" in body or "render_mesh" in body),
                         ("distributed", "dask" in body), ("pandas", "mesh_many" in body)):
        if used:
            require(module)
    body = quick(body, tmp_path)
    if lang == "toml":
        case = tmp_path / "case.toml"
        case.write_text(body)
        fixture = ["--surface", "fixtures/straight.stl", "--centerlines", "fixtures/straight_centerline.csv"]
        args = [str(cli), "mesh", *fixture, "--config", str(case), "--preset", "coarse", "--quiet"]
        args += ["--output", str(tmp_path / "out")]
        done = subprocess.run(args, cwd=REPO, capture_output=True, text=True)
    elif lang == "python":
        script = tmp_path / "block.py"
        script.write_text(body)
        done = subprocess.run([sys.executable, str(script)], cwd=REPO, capture_output=True, text=True, env=environment(cli))
    else:
        ci = (REPO / ".ci" / "run").read_text() + (REPO / "tests" / "python.rs").read_text()
        run = []
        for command in commands(body):
            if command.startswith(BY_CI):
                assert command in ci, f"`{command}` is shown in the docs as CI's own but neither .ci/run nor tests/python.rs runs it"
            else:
                run.append(command)
        if not run:
            return
        script = "set -euo pipefail\n" + CARGO + "\n".join(run) + "\n"
        done = subprocess.run(["bash", "-c", script], cwd=REPO, capture_output=True, text=True, env=environment(cli))
    assert done.returncode == 0, f"{lang} block failed ({done.returncode}):\n{body}\nstdout:\n{done.stdout}\nstderr:\n{done.stderr}"


def test_every_markdown_file_is_read():
    """The blocks come from the README and the guide (a wrong pattern would test nothing)."""
    found = list(blocks())
    assert len(found) >= 20 and any("README.md" in p.id for p in found) and any("guide" in p.id for p in found)

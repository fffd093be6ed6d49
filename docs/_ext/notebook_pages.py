"""Run the notebooks once, at the start of the docs build, and show them as pages.

The notebooks are committed without outputs. Before Sphinx reads its sources,
this extension executes every ``notebooks/*.ipynb`` of the repository with
nbclient, two at a time in separate processes (each notebook is one kernel; the
machine has 2 cores), in the ``notebooks/`` folder so that their relative paths
(``../results/notebooks``) mean what they mean in JupyterLab. The executed
copies go to ``docs/notebooks/`` (ignored by git), where myst-nb renders them
with ``nb_execution_mode = "off"``: the docs show the outputs of this very run.

This is the one place the notebooks run in ``make test`` (pytest no longer
runs them): a cell that raises fails the build, naming the notebook, the cell, its
failing line and the error (:func:`failing_cell`). The fast settings (``GEOVS_FAST=1``:
shorter runs, the same code paths) apply unless the environment sets ``GEOVS_FAST``
itself.
"""

from __future__ import annotations

import os
import re
import shutil
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from sphinx.application import Sphinx
from sphinx.errors import ExtensionError
from sphinx.util import logging
from sphinx.util.typing import ExtensionMetadata

logger = logging.getLogger(__name__)

#: Notebooks run side by side (one kernel each).
PARALLEL_NOTEBOOKS = 2
#: Seconds a cell may run before the build fails.
CELL_TIMEOUT_S = 600
#: Seconds a kernel may take to start (nbclient's default is 60: on 2 busy cores, beside
#: pytest's workers, one start took longer once), and the starts tried: kernels started
#: side by side can also race for the same free TCP port, and then one never answers.
KERNEL_STARTUP_TIMEOUT_S = 180
KERNEL_START_TRIES = 3


def _execute(source: str, target: str) -> tuple[str, float, str | None]:
    """Run one notebook in its own folder and write the executed copy; the error's
    one-line description instead when a cell raises."""
    import nbformat
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError

    # The kernels' and nbclient's chatter (TCP warnings, "Executing notebook") would
    # drown Sphinx's -q output; a failing cell is reported from the exception instead.
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    os.close(devnull)
    start = time.perf_counter()
    attempt = 1
    while True:
        notebook = nbformat.read(source, as_version=4)
        client = NotebookClient(
            notebook,
            timeout=CELL_TIMEOUT_S,
            startup_timeout=KERNEL_STARTUP_TIMEOUT_S,
            kernel_name="python3",
            resources={"metadata": {"path": str(Path(source).parent)}},
        )
        try:
            client.execute()
        except CellExecutionError as e:
            error = failing_cell(notebook) or _last_line(str(e))
            return source, time.perf_counter() - start, error
        except RuntimeError as e:  # jupyter_client: "Kernel didn't respond in N seconds"
            if "Kernel didn't respond" not in str(e):
                raise
            if attempt < KERNEL_START_TRIES:
                attempt += 1
                continue
            error = f"the kernel did not start ({attempt} tries): {_last_line(str(e))}"
            return source, time.perf_counter() - start, error
        nbformat.write(notebook, target)
        return source, time.perf_counter() - start, None


_ANSI = re.compile(r"\x1b\[[0-9;]*m")
#: IPython's frame header for code run from a cell: "Cell In[12], line 20".
_CELL_FRAME = re.compile(r"Cell In\[\d*\], line (\d+)")


def _last_line(text: str) -> str:
    lines = [line for line in _ANSI.sub("", text).splitlines() if line.strip()]
    return lines[-1] if lines else text


def failing_cell(notebook) -> str | None:
    """Where an executed notebook failed, in one line: the cell (its place among all the
    cells and among the code cells, as JupyterLab counts them from 1), the line of that
    cell being run and its text, then the error. None where no cell holds an error."""
    code = 0
    for index, cell in enumerate(notebook.cells, start=1):
        if cell.cell_type != "code":
            continue
        code += 1
        for output in cell.get("outputs", []):
            if output.get("output_type") != "error":
                continue
            where = f"cell {index} (code cell {code})"
            # The traceback's first cell frame is this cell's line (later ones may be
            # functions that earlier cells defined).
            frame = _CELL_FRAME.search(_ANSI.sub("", "\n".join(output.get("traceback", []))))
            if frame:
                number = int(frame.group(1))
                lines = cell.source.splitlines()
                text = lines[number - 1].strip() if 0 < number <= len(lines) else ""
                where += f", line {number}" + (f": {text}" if text else "")
            error = output.get("ename", "Error")
            value = _last_line(output.get("evalue", "")) if output.get("evalue") else ""
            return f"{where}: {error}" + (f": {value}" if value else "")
    return None


def run_notebooks(app: Sphinx) -> None:
    """Execute ``notebooks/*.ipynb`` into ``docs/notebooks/`` (see the module's docstring)."""
    sources = sorted(Path(app.srcdir, "..", "notebooks").resolve().glob("*.ipynb"))
    target_dir = Path(app.srcdir) / "notebooks"
    target_dir.mkdir(exist_ok=True)
    for stale in set(target_dir.glob("*.ipynb")) - {target_dir / s.name for s in sources}:
        stale.unlink()  # a notebook renamed or removed in the repository
    os.environ.setdefault("GEOVS_FAST", "1")
    failures = []
    with ProcessPoolExecutor(PARALLEL_NOTEBOOKS) as pool:
        jobs = [pool.submit(_execute, str(s), str(target_dir / s.name)) for s in sources]
        for job in jobs:
            source, seconds, error = job.result()
            name = Path(source).name
            if error is None:
                logger.info(f"notebook {name}: executed in {seconds:.1f} s")
            else:
                failures.append(f"{name}: {error}")
    if failures:
        raise ExtensionError("a notebook failed: " + "; ".join(failures))


#: The Meshcat recordings the notebooks write (notebook 01: the servo; notebook 06: the
#: arm tracking a moving target; notebook 07: the quadrotor over the landing pad), each
#: copied beside the pages as ``_static/<name>``, where the gallery embeds it.
MESHCAT_RECORDINGS = (
    Path("results", "notebooks", "servo.html"),
    Path("results", "notebooks", "tracking.html"),
    Path("results", "notebooks", "quadrotor.html"),
)
STATIC = Path("_static")


def copy_recording(app: Sphinx, exception: Exception | None) -> None:
    """Put the notebooks' standalone Meshcat recordings beside the pages (the gallery
    embeds them); a build without one (no notebooks run) says so."""
    if exception is not None or app.builder.format != "html":
        return
    for recording in MESHCAT_RECORDINGS:
        source = Path(app.srcdir).parent / recording
        if not source.is_file():
            logger.warning(f"{recording}: missing, the gallery's Meshcat view is empty")
            continue
        shutil.copyfile(source, Path(app.outdir) / STATIC / recording.name)


def setup(app: Sphinx) -> ExtensionMetadata:
    app.connect("builder-inited", run_notebooks)
    app.connect("build-finished", copy_recording)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}

"""Where a benchmark's figures go: ``benchmarks/results/<benchmark>.json``.

Each file holds one run: the machine, the date, the commit, the command, and each
figure with the baseline it is measured against *in the same run* (speed is a ratio
to a baseline timed in the same process, never an absolute time compared across
runs). The docs' performance page is rendered from these files (``docs/_ext``'s
``benchmark-tables`` directive), so it shows one current set of numbers; what
changed between runs goes in the changelog.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


@dataclass
class Figure:
    """One measured figure, and what it is measured against in the same run.

    ``ratio`` is always ``value / baseline_value`` (derived, so a record cannot carry a
    ratio its two figures contradict); ``target`` is what the project aims at, as text
    (``<= 1.2``), or empty.
    """

    name: str
    value: float
    unit: str
    baseline: str = ""
    baseline_value: float | None = None
    target: str = ""
    ratio: float | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        if self.baseline_value:
            self.ratio = self.value / self.baseline_value


def _commit() -> str:
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
        ).stdout.strip()
    except OSError:
        return "unknown"
    return f"{head}{' (modified)' if dirty else ''}" if head else "unknown"


def machine() -> dict:
    """What ran it: enough to know whether two files are comparable."""
    from importlib.metadata import version

    import numba

    try:
        load = os.getloadavg()[0]
    except OSError:
        load = None
    return {
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "load_average_at_end": load,
        "python": platform.python_version(),
        "drake": version("drake"),
        "system": platform.platform(),
    }


def record(benchmark: str, title: str, figures: list[Figure], note: str = "") -> Path:
    """Write ``results/<benchmark>.json`` (atomically) and return its path."""
    data = {
        "benchmark": benchmark,
        "title": title,
        "command": " ".join(["python", *[Path(sys.argv[0]).as_posix(), *sys.argv[1:]]]),
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": _commit(),
        "machine": machine(),
        "note": note,
        "figures": [asdict(f) for f in figures],
    }
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{benchmark}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    tmp.replace(path)
    print(f"figures written to {path.relative_to(RESULTS.parents[0])}")
    return path

"""The wheel as a user gets it: build it, install it outside the checkout, run the CLI.

Usage::

    python tools/check_wheel.py [--keep]

1. ``python -m build``: the sdist, then the wheel built from that sdist; both must
   hold the package data (scenario YAML files, the generated kernels).
2. Two fresh virtual environments in a temporary folder, one with the wheel alone
   (``core``) and one with ``geovs-drake[all]``; ``uv`` installs from its cache
   (``pip`` if ``uv`` is missing, much slower: drake is about 170 MB unpacked).
3. From a folder that is not the checkout, with no ``PYTHONPATH``. In ``core``, the
   commands that need no extra: ``geovs-drake --version``, ``simulate --json --duration
   1`` on the shipped ``default.yaml``, ``demo --duration 1 --no-meshcat``, the shipped
   arm and a brief ``compare`` on the shipped suite (each package-data file found). In
   each environment, the commands that need one: a small ``sweep`` (in ``[all]`` in its
   own process, with Dask importable), ``simulate --sensor rendered`` and the LCM
   ``station`` alone (it needs ``[panda]``). In ``core`` each of those prints the one line
   ``geovs-drake CMD needs PKG: pip install "geovs-drake[EXTRA]"`` with exit code 2
   (``sweep`` must, naming ``[sweep]``: its Parquet dataset needs pyarrow, even with
   ``--workers 1``); in ``[all]`` each must work. No command may print a traceback.

Prints what it did with timings and the wheel's size; exits 1 on any failure.
``tests/test_wheel.py`` runs it (``make wheel-check``, part of ``make test``).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The one line a command prints when an extra is missing (geovs_drake._optional).
MISSING_EXTRA = re.compile(r'^geovs-drake (\w+) needs (\S+): pip install "geovs-drake\[(\w+)\]"$')
WORKED = (0, 3)  # converged, or ran and did not converge (1 s is short)
EXIT_BAD_INPUT = 2


@dataclass
class Report:
    """What the check did: one line per step, the failures, the wheel's size."""

    lines: list[str] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    wheel_bytes: int = 0
    wall_s: float = 0.0

    def fail(self, what: str) -> None:
        self.failures.append(what)
        self.lines.append(f"FAIL {what}")


def _run(
    cmd: list[str], cwd: Path, timeout: float = 300.0
) -> tuple[subprocess.CompletedProcess, float]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["MPLBACKEND"] = "Agg"
    start = time.perf_counter()
    run = subprocess.run(
        cmd, cwd=cwd, env=env, capture_output=True, text=True, stdin=subprocess.DEVNULL,
        timeout=timeout,
    )  # fmt: skip
    return run, time.perf_counter() - start


def _uv() -> list[str] | None:
    if importlib.util.find_spec("uv") is not None:
        return [sys.executable, "-m", "uv"]
    found = shutil.which("uv")
    return [found] if found else None


def build(out: Path, report: Report) -> Path:
    """sdist and wheel into ``out``; returns the wheel. Checks both hold the package data."""
    run, dt = _run([sys.executable, "-m", "build", "--outdir", str(out), str(ROOT)], cwd=out)
    if run.returncode != 0:
        raise RuntimeError(f"python -m build failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}")
    wheel = next(out.glob("geovs_drake-*.whl"))
    sdist = next(out.glob("geovs_drake-*.tar.gz"))
    report.wheel_bytes = wheel.stat().st_size
    report.lines.append(
        f"python -m build: {dt:.1f} s; {wheel.name} {report.wheel_bytes / 1e3:.0f} kB, "
        f"{sdist.name} {sdist.stat().st_size / 1e3:.0f} kB"
    )
    package = ROOT / "geovs_drake"
    wanted = {
        p.relative_to(ROOT).as_posix()
        for p in package.rglob("*")
        if p.suffix in (".py", ".yaml", ".csv") and "__pycache__" not in p.parts
    }
    for must in (
        "geovs_drake/scenarios/default.yaml",
        "geovs_drake/geometry/_generated/kernels.py",
    ):
        if must not in wanted:
            report.fail(f"the checkout has no {must}")
    in_wheel = set(zipfile.ZipFile(wheel).namelist())
    prefix = sdist.name.removesuffix(".tar.gz") + "/"
    with tarfile.open(sdist) as tar:
        in_sdist = {n.removeprefix(prefix) for n in tar.getnames()}
    for name, files in (("wheel", in_wheel), ("sdist", in_sdist)):
        missing = sorted(wanted - files)
        if missing:
            report.fail(f"the {name} lacks {missing}")
    if "CHANGELOG.md" not in in_sdist:
        report.fail("the sdist lacks CHANGELOG.md")
    return wheel


def make_env(kind: str, wheel: Path, tmp: Path) -> tuple[Path, str]:
    """A fresh venv under ``tmp`` with the wheel (``kind`` "core") or ``[all]``."""
    env = tmp / f"venv-{kind}"
    python = env / "bin" / "python"
    spec = f"geovs-drake{'[all]' if kind == 'all' else ''} @ {wheel.as_uri()}"
    uv = _uv()
    start = time.perf_counter()
    if uv is not None:
        cmds = [
            uv + ["venv", "--quiet", "--python", sys.executable, str(env)],
            uv + ["pip", "install", "--quiet", "--python", str(python), spec],
        ]
        tool = "uv"
    else:
        cmds = [
            [sys.executable, "-m", "venv", str(env)],
            [str(python), "-m", "pip", "install", "--quiet", spec],
        ]
        tool = "pip"
    for cmd in cmds:
        run, _ = _run(cmd, cwd=tmp, timeout=900)
        if run.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed:\n{run.stderr[-3000:]}")
    return env, f"{kind}: venv + install with {tool} {time.perf_counter() - start:.1f} s"


def _not_json(constant: str) -> None:
    raise ValueError(f"{constant} is not JSON")


def _check(report: Report, kind: str, label: str, run: subprocess.CompletedProcess, dt: float,
           may_need_extra: bool) -> str:  # fmt: skip
    """Record one command: it worked, or (``may_need_extra``) named its extra in one line."""
    what = f"{kind}: {label}"
    text = run.stdout + run.stderr
    if "Traceback" in text:
        report.fail(f"{what} printed a traceback (exit {run.returncode}):\n{run.stderr[-4000:]}")
        return "traceback"
    if run.returncode in WORKED:
        report.lines.append(f"{what}: worked (exit {run.returncode}), {dt:.1f} s")
        return "worked"
    lines = run.stderr.strip().splitlines()
    match = MISSING_EXTRA.match(lines[0]) if len(lines) == 1 else None
    if may_need_extra and run.returncode == EXIT_BAD_INPUT and match:
        report.lines.append(f"{what}: exit 2, {lines[0]!r}, {dt:.1f} s")
        return f"needs {match.group(3)}"
    report.fail(f"{what}: exit {run.returncode}\nstdout: {run.stdout[-2000:]}\nstderr: "
                f"{run.stderr[-2000:]}")  # fmt: skip
    return "failed"


def exercise(kind: str, env: Path, tmp: Path, report: Report, version: str) -> None:
    """Run the CLI of the installed wheel from ``tmp/run-kind`` (not the checkout)."""
    cwd = tmp / f"run-{kind}"
    cwd.mkdir()
    cli = str(env / "bin" / "geovs-drake")
    python = str(env / "bin" / "python")
    core = kind == "core"

    if core:  # the same entry point in both environments: once is enough
        run, dt = _run([cli, "--version"], cwd)
        _check(report, kind, "--version", run, dt, may_need_extra=False)
        if run.stdout.strip() != f"geovs-drake {version}":
            report.fail(f"{kind}: --version printed {run.stdout.strip()!r}, the wheel is {version}")

    simulate = [cli, "simulate", "--json", "--duration", "1"]
    if core:  # the shipped scenario file, found through importlib.resources
        probe = (
            "import geovs_drake, geovs_drake.scenarios as s, importlib.metadata as m;"
            "print(s.path('default')); print(geovs_drake.__file__); print(m.version('geovs-drake'))"
        )
        run, _ = _run([python, "-c", probe], cwd)
        default, package_file, meta = (run.stdout.splitlines() + ["", "", ""])[:3]
        if run.returncode != 0 or not Path(default).is_file():
            report.fail(f"core: scenarios.path('default') failed: {run.stderr[-2000:]}")
        elif not Path(package_file).is_relative_to(env) or not Path(default).is_relative_to(env):
            report.fail(f"core: geovs_drake imported from {package_file}, not from {env}")
        elif meta != version:
            report.fail(f"core: installed metadata says {meta}, the wheel is {version}")
        else:
            simulate += ["--config", default]
    if core:  # the loop, once: the [all] environment's commands below run it too
        run, dt = _run(simulate, cwd)
        label = " ".join(simulate[1:]).replace(str(tmp), "TMP")
        if _check(report, kind, label, run, dt, False) == "worked":
            try:
                status = json.loads(run.stdout)["status"]
            except (ValueError, KeyError):
                report.fail(f"{kind}: simulate --json printed no JSON result: {run.stdout[-500:]}")
            else:
                report.lines[-1] += f", status {status}"
        # The commands that need no extra: once, where only the core is installed.
        _exercise_core_only(cli, cwd, report)

    # A small sweep: needs the `sweep` extra. In core, on Dask's LocalCluster it must name
    # the extra (dask is not core), and without Dask too (its Parquet dataset needs
    # pyarrow). In [all], in this process (--workers 1: the Parquet dataset from the
    # installed wheel), and Dask importable from the extra; the LocalCluster itself runs
    # in tests/test_sweep.py, from the checkout (2 worker processes here cost 18 s).
    sweep = [cli, "sweep", "--starts", "2", "--chunk", "1", "--duration", "0.5",
             "--engine", "drake", "--out", str(cwd / "sweep"), "--json"]  # fmt: skip
    if core:
        run, dt = _run(sweep, cwd)
        outcome = _check(report, kind, "sweep --workers 2 (Dask)", run, dt, core)
        if outcome != "needs sweep":
            report.fail(
                f"core: sweep on Dask should need the sweep extra (dask is not core): {outcome}"
            )
    run, dt = _run(sweep + ["--workers", "1"], cwd)
    outcome = _check(report, kind, "sweep --workers 1 (no Dask)", run, dt, core)
    if core and outcome != "needs sweep":
        report.fail(f"core: the sweep's Parquet dataset should need the sweep extra: {outcome}")
    if core and (cwd / "sweep").exists():
        report.fail("core: a sweep refused for a missing extra left its --out folder")
    if not core:
        run, dt = _run([python, "-c", "import dask.distributed"], cwd)
        _check(report, kind, "import dask.distributed (the sweep extra)", run, dt, False)

    # The LCM station alone on an in-process bus (the shipped panda_lcm.yaml): the Panda's
    # model needs the `panda` extra; with it the station holds the arm, hears no
    # command, and says so in strict JSON.
    station = [cli, "station", "--lcm", "memq://", "--duration", "0.2", "--json"]
    run, dt = _run(station, cwd)
    outcome = _check(report, kind, "station --lcm memq://", run, dt, core)
    if core and outcome != "needs panda":
        report.fail(f"core: the station's Panda should need the panda extra: {outcome}")
    if outcome == "worked":
        try:
            heard = json.loads(run.stdout, parse_constant=_not_json)["commands_received"]
        except (ValueError, KeyError):
            report.fail(f"{kind}: station --json printed no strict JSON: {run.stdout[-500:]}")
        else:
            if heard != 0:
                report.fail(f"{kind}: a station alone heard {heard} commands")

    # The rendered camera (RgbdSensor, VTK/EGL, OpenCV): needs the `vision` extra.
    rendered = [cli, "simulate", "--sensor", "rendered", "--duration", "0.2", "--json"]
    run, dt = _run(rendered, cwd)
    outcome = _check(report, kind, "simulate --sensor rendered", run, dt, core)
    if core and outcome != "needs vision":
        report.fail(f"core: the rendered camera should need the vision extra: {outcome}")


def _exercise_core_only(cli: str, cwd: Path, report: Report) -> None:
    """demo, compare and the arm: they need no extra, so the core environment runs them
    (the [all] one adds nothing they use) and each package-data file is found."""
    kind = "core"
    demo_out = cwd / "demo"
    run, dt = _run([cli, "demo", "--duration", "1", "--no-meshcat", "--out", str(demo_out)], cwd)
    if _check(report, kind, "demo --duration 1 --no-meshcat", run, dt, False) == "worked":
        for name in ("summary.json", "run.png", "image_view.png", "nf_slices.png"):
            if not (demo_out / name).is_file():
                report.fail(f"{kind}: demo wrote no {name}")

    # The arm shipped as package data (geovs_drake/models/ur5.urdf), briefly.
    arm = [cli, "simulate", "--carrier", "arm", "--plant", "kinematic", "--duration", "0.5"]
    _check(report, kind, "simulate --carrier arm (shipped arm)", *_run(arm, cwd), False)

    # Every law on the shipped suite (package data), briefly, in this process.
    compare_out = cwd / "compare"
    compare = [cli, "compare", "--plant", "kinematic", "--duration", "0.2", "--workers", "1",
               "--out", str(compare_out)]  # fmt: skip
    run, dt = _run(compare, cwd)
    if _check(report, kind, "compare (shipped suite)", run, dt, False) == "worked":
        for name in ("table.md", "table.csv"):
            if not (compare_out / name).is_file():
                report.fail(f"{kind}: compare wrote no {name}")


def check(tmp: Path) -> Report:
    """Build, install twice and exercise; the environments run side by side."""
    report = Report()
    start = time.perf_counter()
    dist = tmp / "dist"
    dist.mkdir()
    wheel = build(dist, report)
    version = wheel.name.split("-")[1]

    def one(kind: str) -> Report:
        sub = Report()
        env, line = make_env(kind, wheel, tmp)
        sub.lines.append(line)
        exercise(kind, env, tmp, sub, version)
        return sub

    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        for sub in pool.map(one, ("core", "all")):
            report.lines += sub.lines
            report.failures += sub.failures
    report.wall_s = time.perf_counter() - start
    report.lines.append(f"wheel check: {report.wall_s:.1f} s wall")
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", action="store_true", help="keep the temporary folder")
    args = parser.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="geovs-wheel-check-"))
    try:
        report = check(tmp)
    finally:
        if args.keep:
            print(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    print("\n".join(report.lines))
    return 1 if report.failures else 0


if __name__ == "__main__":
    sys.exit(main())

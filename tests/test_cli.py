"""The command line's contract: exit codes, one-line errors for bad input, --version, help."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from pydrake.common.yaml import yaml_dump_typed

from geovs_drake import cli
from geovs_drake.cli import EXIT_CODES, main
from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.loop import resolve
from geovs_drake.scenario import (
    AXES,
    CarrierConfig,
    Ibvs,
    Kinematic,
    Pinhole,
    PoseConfig,
    ScenarioConfig,
    load_scenario,
)
from geovs_drake.simulation import SimulationResult, simulate


def _assert_one_line_error(err: str, *needles: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


BAD_CONFIGS = {
    "unknown-key": ("colour: red\n", ["colour", "unknown field"]),
    "unknown-nested-key": ("control:\n  dampening: [1, 1, 1, 1, 1, 1]\n", ["control.dampening"]),
    "malformed-yaml": ("control: {damping: [1, 2\n", ["malformed YAML", "line"]),
    "damping-not-a-list": (
        "control:\n  damping: abc\n",
        ["control.damping: expected a list of 6 numbers, got 'abc'"],
    ),
    "damping-five": ("control:\n  damping: [1, 1, 1, 1, 1]\n", ["control.damping", "6 numbers"]),
    "damping-negative": (
        "control:\n  damping: [1, 1, 1, 1, 1, -1]\n",
        ["control.damping", "non-negative", "-1"],
    ),
    "duration-not-a-number": ("duration: soon\n", ["duration", "'soon'"]),
    "duration-zero": ("duration: 0\n", ["duration", "> 0"]),
    "integrator": (
        "simulator:\n  integration_scheme: leapfrog\n",
        ["simulator.integration_scheme", "'leapfrog'", "runge_kutta3"],
    ),
    "log-rate-zero": ("log_rate: 0\n", ["log_rate", "> 0", "0.0"]),
    "log-rate-negative": ("log_rate: -5\n", ["log_rate", "-5"]),
    "inertia-two": (
        "carrier: !FreeRig\n  inertia_diagonal: [0.02, 0.02]\n",
        ["carrier.inertia_diagonal", "3"],
    ),
    "inertia-zero": (
        "carrier: !FreeRig\n  inertia_diagonal: [0.02, 0, 0.02]\n",
        ["carrier.inertia_diagonal"],
    ),
    "root-a-list": ("- 1\n- 2\n", ["expected a mapping"]),
}


@pytest.mark.parametrize("name", list(BAD_CONFIGS))
def test_simulate_bad_config_exits_2_with_one_line(name, tmp_path, capsys, run_cli):
    text, needles = BAD_CONFIGS[name]
    path = tmp_path / "scenario.yaml"
    path.write_text(text)
    code, out, err = run_cli("simulate", "--config", str(path))
    assert code == 2, err
    assert out == ""
    _assert_one_line_error(err, *needles)


def test_simulate_missing_config_exits_2_with_one_line(tmp_path, capsys, run_cli):
    missing = tmp_path / "nope.yaml"
    code, out, err = run_cli("simulate", "--config", str(missing))
    assert code == 2 and out == ""
    _assert_one_line_error(err, str(missing), "no such file")


def test_simulate_good_config_overridden_by_options(tmp_path, capsys, run_cli):
    path = tmp_path / "scenario.yaml"
    path.write_text("plant: kinematic\nduration: 0\nsimulator:\n  accuracy: 1e-6\n")
    # The file's bad duration is overridden by --duration: the run goes ahead.
    code, out, err = run_cli("simulate", "--config", str(path), "--duration", "12")
    assert code == 0, err
    assert out.startswith("nf on the kinematic plant: converged")


def test_simulate_exit_0_when_converged(capsys, run_cli):
    code, out, err = run_cli("simulate", "--plant", "kinematic", "--duration", "12")
    assert code == 0, err
    assert out.startswith("nf on the kinematic plant: converged")


@pytest.mark.parametrize(
    ("argv", "status"),
    [
        (["--duration", "0.5"], "not_converged"),
        (["--duration", "3", "--initial-velocity=0,0,0,12,0,0"], "left_domain"),
    ],
    ids=["not-converged", "left-domain"],
)
def test_simulate_exit_3_when_it_ran_and_did_not_converge(argv, status, capsys, run_cli):
    code, out, err = run_cli("simulate", *argv)
    assert code == 3, err
    assert out.startswith(f"nf on the dynamic plant: {status} ")


@pytest.mark.parametrize(
    ("status", "code"),
    [
        ("converged", 0),
        ("not_converged", 3),
        ("left_domain", 3),
        ("lost_visibility", 3),
        ("non_finite", 3),
    ],
)
def test_exit_code_of_every_status(status, code):
    assert cli.exit_code_of(status) == code


def test_simulate_exit_130_when_interrupted(monkeypatch, capsys, run_cli):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("geovs_drake.cli.simulate.simulate", interrupted)
    code, out, err = run_cli("simulate", "--duration", "1")
    assert code == 130
    _assert_one_line_error(err, "interrupted")


def test_demo_exit_3_when_the_run_did_not_converge(monkeypatch, tmp_path, capsys, run_cli):
    import geovs_drake.demo

    class _Result:
        status = "left_domain"

    def fake_run_demo(
        out: str,
        duration: float | None,
        meshcat: bool,
        rendered: bool = True,
        carrier: CarrierConfig | None = None,
    ) -> SimulationResult:
        return _Result()  # type: ignore[return-value]

    monkeypatch.setattr(geovs_drake.demo, "run_demo", fake_run_demo)
    code, _, err = run_cli("demo", "--out", str(tmp_path / "d"), "--duration", "1")
    assert code == 3, err


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["--duration", "-1"], ["--duration", "-1"]),
        (["--duration", "0"], ["--duration", "> 0"]),
        (["--duration", "nan"], ["--duration", "nan"]),
        (["--duration", "inf"], ["--duration", "inf"]),
    ],
    ids=["negative", "zero", "nan", "inf"],
)
def test_demo_bad_duration_exits_2_and_creates_nothing(argv, needles, tmp_path, capsys, run_cli):
    out_dir = tmp_path / "x"
    code, out, err = run_cli("demo", "--out", str(out_dir), *argv)
    assert code == 2 and out == ""
    _assert_one_line_error(err, *needles)
    assert not out_dir.exists()
    assert list(tmp_path.iterdir()) == []


def test_demo_out_an_existing_file_exits_2(tmp_path, capsys, run_cli):
    target = tmp_path / "results"
    target.write_text("not a folder")
    code, _, err = run_cli("demo", "--out", str(target), "--duration", "1")
    assert code == 2
    _assert_one_line_error(err, "--out", str(target), "not a directory")
    assert target.read_text() == "not a folder"


def test_demo_out_under_a_file_exits_2(tmp_path, capsys, run_cli):
    blocker = tmp_path / "file"
    blocker.write_text("")
    code, _, err = run_cli("demo", "--out", str(blocker / "x"), "--duration", "1")
    assert code == 2
    _assert_one_line_error(err, "--out", str(blocker), "not a directory")
    assert sorted(tmp_path.iterdir()) == [blocker]


def test_demo_out_under_a_read_only_folder_exits_2(tmp_path, capsys, run_cli):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if _can_write(locked):
            pytest.skip("running as a user who can write anywhere (root)")
        code, _, err = run_cli("demo", "--out", str(locked / "x"), "--duration", "1")
        assert code == 2
        _assert_one_line_error(err, "--out", "not writable")
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o700)


def _can_write(folder: Path) -> bool:
    try:
        (folder / "probe").write_text("")
    except PermissionError:
        return False
    (folder / "probe").unlink()
    return True


def test_version_prints_the_package_version(capsys):
    """--version shows geovs_drake.__version__, the one place the version is written:
    pyproject.toml reads it (the wheel check compares the installed metadata)."""
    import tomllib

    import geovs_drake

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert out.strip() == f"geovs-drake {geovs_drake.__version__}"
    project = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    assert "version" not in project["project"] and "version" in project["project"]["dynamic"]
    attr = project["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "geovs_drake.__version__"
    changelog = (Path(__file__).resolve().parents[1] / "CHANGELOG.md").read_text()
    assert f"## {geovs_drake.__version__}" in changelog


def _option_entries(help_text: str) -> dict[str, str]:
    """Option -> its help, joined over continuation lines, from an ``options:`` block."""
    block = help_text.split("options:\n")[1].split("\n\n")[0]
    entries: dict[str, str] = {}
    name = ""
    for line in block.splitlines():
        if line.startswith("  -"):
            name = line.split()[0].rstrip(",")
            entries[name] = line
        else:
            entries[name] += " " + line.strip()
    return entries


@pytest.mark.parametrize("command", ["simulate", "demo", "sweep"])
def test_help_shows_every_default_and_the_exit_codes(command, capsys):
    with pytest.raises(SystemExit) as e:
        main([command, "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    entries = _option_entries(text)
    assert "--duration" in entries and "--out" in entries if command == "demo" else True
    for name, entry in entries.items():
        if name != "-h":
            assert "(default:" in entry, entry
    assert "[s]" in entries["--duration"]
    if command == "simulate":
        for name in ("--initial", "--goal"):
            assert "[m, rad]" in entries[name], name
        assert "[rad/s, m/s]" in entries["--initial-velocity"]
    table = text.split("exit codes:")[1]
    for code in EXIT_CODES:
        assert f"  {code} " in table, code


def test_readme_lists_the_exit_codes():
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    section = readme.split("## Command line")[1].split("\n## ")[0]
    for code in EXIT_CODES:
        assert f"`{code}`" in section, code


def test_progress_off_a_terminal_prints_sparse_integer_lines(capsys):
    """No carriage returns and no float drift in a log: whole counts, a line at most
    every min_interval_s, and always the last."""
    from geovs_drake.progress import Progress

    p = Progress(30, "starts", "geovs-drake sweep", min_interval_s=3600.0)
    for done in (5, 7, 12, 12, 29, 30):
        p.update_to(done)
    p.close()
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = err.strip().splitlines()
    assert lines[0].startswith("geovs-drake sweep: 5/30 starts") and lines[-1].startswith(
        "geovs-drake sweep: 30/30 starts"
    )
    assert len(lines) == 2  # the first, then nothing for an hour but the last


def test_demo_progress_is_sparse_in_a_log(tmp_path, run_cli, monkeypatch):
    """`demo` with stderr to a file (not a TTY): plain progress lines, no tqdm bar."""
    from geovs_drake import plotting

    out = tmp_path / "demo"
    # In this process (capsys's stderr is no TTY either: a subprocess costs the imports),
    # and without the figures, which test_demo_and_plots.py checks: what is read here is
    # the progress of the run.
    for name in ("plot_image_view", "plot_run", "plot_navigation_slices", "write_block_diagram"):
        monkeypatch.setattr(plotting, name, lambda *args, **kwargs: [])
    run = run_cli("demo", "--out", str(out), "--duration", "0.5", "--no-meshcat", "--no-rendered")
    assert run.code == cli.EXIT_NOT_CONVERGED, run.err  # 0.5 s is too short
    assert "\r" not in run.err
    assert "dynamic servo: 100 % of 0.5 s simulated" in run.err


def test_progress_waits_for_its_delay_and_stays_quiet_on_short_work(monkeypatch, capsys):
    """delay_s: nothing before it (a short run prints nothing at all), then sparse lines."""
    from geovs_drake import progress as progress_module

    clock = {"now": 100.0}
    monkeypatch.setattr(progress_module.time, "perf_counter", lambda: clock["now"])

    def run(steps: list[tuple[float, int]]) -> list[str]:
        clock["now"] = 100.0
        p = progress_module.Progress(100, "starts", "geovs-drake sweep", delay_s=3.0)
        for t, done in steps:
            clock["now"] = 100.0 + t
            p.update_to(done)
        p.close()
        return capsys.readouterr().err.splitlines()

    assert run([(0.1, 10), (1.0, 60), (2.9, 100)]) == []  # done within the delay: quiet
    lines = run([(1.0, 10), (2.9, 50), (3.1, 60), (4.0, 70), (5.2, 80), (5.3, 100)])
    assert lines == [
        "geovs-drake sweep: 60/100 starts after 3.1 s",  # the first after the delay
        "geovs-drake sweep: 80/100 starts after 5.2 s",  # min_interval_s = 2 later
        "geovs-drake sweep: 100/100 starts after 5.3 s",  # and always the end
    ]


def test_a_horizon_s_progress_is_a_percentage_of_the_simulated_time(monkeypatch, capsys):
    """The simulated horizon's progress is the share of it simulated, a percentage (the
    line read ``66/100 %``, a count of a percent): at t = 19.8 s of 30 s, 66 %."""
    from geovs_drake import progress as progress_module

    clock = {"now": 0.0}
    monkeypatch.setattr(progress_module.time, "perf_counter", lambda: clock["now"])
    p = progress_module.HorizonProgress(30.0, "geovs-drake simulate", delay_s=3.0)
    horizon_s, wall = 30.0, {19.8: 3.0, 25.5: 5.0, 30.0: 5.5}  # simulated t -> wall [s]
    for t, now in wall.items():
        clock["now"] = now
        p(t)
    p.close()
    lines = capsys.readouterr().err.splitlines()
    shares = [round(100 * t / horizon_s) for t in wall]  # 66, 85, 100: the truth
    assert lines == [
        f"geovs-drake simulate: {share} % of 30 s simulated after {now:.1f} s"
        for share, now in zip(shares, wall.values(), strict=True)
    ]


def test_simulate_progress_goes_to_stderr_and_changes_nothing_else(monkeypatch, capsys, run_cli):
    """`simulate --json` off a terminal: progress lines on stderr only past the delay; stdout
    is the same one JSON line, and the run the same, steps included."""
    import json
    import re

    argv = ["simulate", "--json", "--duration", "5"]
    code, out_quiet, err_quiet = run_cli(*argv)
    assert err_quiet == ""  # well under SIMULATE_PROGRESS_DELAY_S: no progress at all
    monkeypatch.setattr(cli, "SIMULATE_PROGRESS_DELAY_S", 0.0)
    code_shown, out, err = run_cli(*argv)
    assert code_shown == code
    lines = err.splitlines()
    assert 2 <= len(lines) <= 3 and "\r" not in err, err  # first, (maybe one more), last
    line = r"geovs-drake simulate: \d+ % of 5 s simulated after \d+\.\d s"
    assert all(re.fullmatch(line, x) for x in lines), lines
    assert lines[-1].startswith("geovs-drake simulate: 100 % of 5 s simulated")
    assert len(out.splitlines()) == 1
    quiet, shown = json.loads(out_quiet), json.loads(out)
    quiet.pop("wall_time_s"), shown.pop("wall_time_s")
    assert shown == quiet  # progress from the monitor: the integration is not cut in pieces


@pytest.mark.parametrize("columns", ["60", "80", "120"])
@pytest.mark.parametrize("command", [[], ["simulate"], ["demo"], ["sweep"]])
def test_help_never_breaks_a_word_at_its_hyphen(command, columns, monkeypatch, capsys):
    """argparse wraps at hyphens by default, which printed `--initial-` / `velocity=-0.1`:
    an option cut in two, wrong when copied. Every help text keeps its words whole."""
    monkeypatch.setenv("COLUMNS", columns)
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    text = capsys.readouterr().out
    assert not re.search(r"\w-\n", text), text
    if command == ["simulate"]:
        assert "--initial-velocity=-0.1,..." in text
    if command:
        # What the command does, in its own help (not only in the list of commands).
        assert text.split("\n\n")[1].strip() and not text.split("\n\n")[1].startswith("options")


ROOT = Path(__file__).resolve().parents[1]


def _synopsis(text: str, heading: str) -> dict[str, str]:
    """Command -> its entry in the first code block after ``heading``: the synopsis."""
    block = text.split(heading)[1].split("```")[1]
    entries = re.split(r"^geovs-drake ", block, flags=re.M)[1:]
    return {e.split()[0]: e for e in entries if not e.startswith("--")}


def _visible_options(parser) -> dict[str, tuple | None]:
    """A parser's options its --help shows (not -h, not a deprecated hidden one): the
    long spelling -> its choices (None: a value or a switch)."""
    import argparse

    return {
        a.option_strings[-1]: tuple(a.choices) if a.choices else None
        for a in parser._actions
        if a.option_strings and a.help != argparse.SUPPRESS and a.dest != "help"
    }


def _check_synopsis(command: str, entry: str, options: dict, complete: bool) -> None:
    """Each ``[--option a|b]`` of ``entry`` is an option of ``command``, with exactly its
    choices where it has choices; ``complete``: every option is there."""
    named = dict(re.findall(r"\[(--[\w-]+)(?: ([^\]]+))?\]", entry))
    for option, arg in named.items():
        assert option in options, (command, option)
        if options[option] is not None:
            assert sorted(arg.split("|")) == sorted(options[option]), (command, option)
    if complete:
        assert set(options) <= set(named), (command, set(options) - set(named))


def test_every_command_and_option_is_in_the_docs_synopsis():
    """docs/command-line.md promises each command's synopsis: every command, and each of
    its --help's options with its choices (the moving target's, station and controller
    were missing)."""
    synopsis = _synopsis((ROOT / "docs" / "command-line.md").read_text(), "# The command line")
    commands = cli.subcommands()
    assert set(synopsis) == set(commands)
    for command, parser in commands.items():
        _check_synopsis(command, synopsis[command], _visible_options(parser), complete=True)


def test_the_readme_gives_each_command_a_line_of_real_options():
    """The README: a line per command, every command; what it names is real, with its
    choices (the whole synopsis is the docs')."""
    synopsis = _synopsis((ROOT / "README.md").read_text(), "## Command line")
    commands = cli.subcommands()
    assert set(synopsis) == set(commands)
    for command, entry in synopsis.items():
        assert entry.strip().count("\n") == 0, entry
        _check_synopsis(command, entry, _visible_options(commands[command]), complete=False)


def test_the_generated_reference_has_every_command_and_option():
    """docs/cli.rst (the source the reference is built from) has a ``cli-help`` of each
    command, and the text that directive shows (cli.help_text, what docs/_ext calls)
    names each option its parser has."""
    rst = (ROOT / "docs" / "cli.rst").read_text()
    documented = re.findall(r"^\.\. cli-help::[ \t]*(\S*)$", rst, flags=re.M)
    commands = cli.subcommands()
    assert sorted(documented) == sorted(["", *commands])
    extension = (ROOT / "docs" / "_ext" / "geovs_docs.py").read_text()
    assert "help_text(" in extension  # the directive shows cli.help_text, tested here
    for command, parser in commands.items():
        text = cli.help_text(command)
        for option in _visible_options(parser):
            assert re.search(rf"\[{option}[ \]]", text), (command, option)


@pytest.mark.parametrize(
    "buffered",
    # One stays in make test (its budget), both run in make test-slow.
    [pytest.param(True, marks=pytest.mark.slow), False],
    ids=["buffered", "unbuffered"],
)
def test_a_closed_pipe_ends_quietly_with_its_own_exit_code(buffered):
    """`geovs-drake ... | head` closes stdout early: no traceback, exit code 141, whether
    stdout is block-buffered (a pipe's default: the write fails at the last flush) or
    not (PYTHONUNBUFFERED, set on some machines: it fails at the print)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    if not buffered:
        env["PYTHONUNBUFFERED"] = "1"
    proc = subprocess.Popen(
        [sys.executable, "-m", "geovs_drake.cli", "simulate", "--json", "--duration", "0.2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    proc.stdout.close()  # the reader is gone before the result is written
    err = proc.stderr.read()
    assert proc.wait() == 141, err
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


def test_the_commands_exit_keeps_its_code_its_output_its_threads_and_atexit(tmp_path):
    """The console script leaves without CPython's finalisation (cli.entry), but only
    after what a normal exit does that a user can see: a worker thread's work finished,
    the atexit handlers run, a pipe's block-buffered stdout flushed, the exit code kept."""
    code = (
        "import atexit, sys, threading, time\n"
        "from pathlib import Path\n"
        "from geovs_drake import cli\n"
        f"out = Path({str(tmp_path)!r})\n"
        "atexit.register(lambda: (out / 'atexit').write_text('ran'))\n"
        "def work():\n"
        "    time.sleep(0.3)\n"
        "    (out / 'thread').write_text('done')\n"
        "threading.Thread(target=work).start()\n"
        "sys.argv = ['geovs-drake', 'simulate', '--duration', '0.01', '--initial', 'x']\n"
        "print('buffered line')\n"
        "cli.entry()\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 2, proc.stderr  # bad input's code, through the fast exit
    assert proc.stdout == "buffered line\n" and "--initial" in proc.stderr
    assert (tmp_path / "atexit").read_text() == "ran"
    assert (tmp_path / "thread").read_text() == "done"


# ------------------------------------------ simulate's JSON and its one-line errors
JSON_FIELDS = {
    "converged",
    "final_position_error_m",
    "final_rotation_error_rad",
    "min_fov_margin",
    "min_occlusion_margin",
    "min_visibility",
    "left_domain",
    "status",
    "sim_time_s",
    "wall_time_s",
    "steps",
    "lyapunov_monotone",
    "max_energy",
}


def test_cli_json_has_every_field_and_is_true_to_the_run(run_cli):
    initial = "-0.1,0.05,-0.7,0.1,-0.05,1.2"
    out = run_cli("simulate", "--json", f"--initial={initial}", "--duration", "12")
    assert out.code == 0, out.err
    lines = out.out.strip().splitlines()
    assert len(lines) == 1
    s = json.loads(lines[0])
    assert JSON_FIELDS <= set(s)
    # The same run through the Python API is deterministic: same numbers.
    values = [float(v) for v in initial.split(",")]
    r = simulate(
        ScenarioConfig(duration=12.0, initial=PoseConfig(xyz=values[:3], rpy=values[3:]))
    ).summary()
    for key in JSON_FIELDS - {"wall_time_s"}:
        if isinstance(r[key], bool | str | int):
            assert s[key] == r[key], key
        else:
            assert s[key] == pytest.approx(r[key], rel=1e-9, abs=1e-15), key
    assert s["converged"] is True and s["left_domain"] is False
    assert s["sim_time_s"] == 12.0


def test_cli_one_line_and_kinematic(run_cli):
    out = run_cli("simulate", "--plant", "kinematic", "--duration", "12")
    assert out.code == 0, out.err
    assert len(out.out.strip().splitlines()) == 1
    assert out.out.startswith("nf on the kinematic plant: converged")


def test_cli_start_outside_domain_exits_2_with_one_line(run_cli):
    out = run_cli("simulate", "--initial=0,0,-3,0,0,0")
    assert out.code == 2
    assert out.out == ""
    lines = out.err.strip().splitlines()
    assert len(lines) == 1 and "lam_min margin" in lines[0]
    bad = run_cli("simulate", "--initial=0,0,-0.5,0,0")
    assert bad.code == 2 and "expected 6" in bad.err


def test_cli_initial_velocity_json_round_trip(run_cli):
    twist = "-0.2,0.1,0.3,0.05,-0.1,0.02"
    out = run_cli("simulate", "--json", f"--initial-velocity={twist}", "--duration", "10")
    assert out.code == 0, out.err
    lines = out.out.strip().splitlines()
    assert len(lines) == 1
    s = json.loads(lines[0])
    config = ScenarioConfig(duration=10.0, initial_velocity=[float(v) for v in twist.split(",")])
    r = simulate(config).summary()
    for key in (JSON_FIELDS | {"initial_energy", "energy_bound", "energy_guarantee"}) - {
        "wall_time_s"
    }:
        if isinstance(r[key], bool | str | int):
            assert s[key] == r[key], key
        else:
            assert s[key] == pytest.approx(r[key], rel=1e-9, abs=1e-15), key
    # The flag reached the plant: E0 is the moving start's, above k_p phi0 at rest.
    nf = NavigationFunction(
        config.domain.to_domain(), config.goal_features(), config.navigation.to_gains()
    )
    at_rest = config.control.potential_gain * float(nf.value(config.initial_features()))
    assert s["initial_energy"] > at_rest + 1e-6
    assert s["energy_guarantee"] is True and s["converged"] is True


@pytest.mark.parametrize(
    "args",
    [
        ["--initial-velocity=0,0,0,0.1,0"],
        ["--initial-velocity", "abc"],
        ["--initial-velocity", "-0.1,0,0,0,0,0"],
        ["--plant", "kinematic", "--initial-velocity=0,0,0,0.1,0,0"],
    ],
    ids=["five-numbers", "abc", "negative-without-equals", "kinematic"],
)
def test_cli_bad_initial_velocity_exits_2_with_one_line(args, run_cli):
    out = run_cli("simulate", *args, "--duration", "1")
    assert out.code == 2
    assert out.out == ""
    lines = out.err.strip().splitlines()
    assert len(lines) == 1, out.err
    assert "initial-velocity" in lines[0] or "initial_velocity" in lines[0]
    assert "Traceback" not in out.err


# ------------------------------------------- the scenario in layers: --scenario-text
@pytest.fixture
def loaded(monkeypatch):
    """The scenario `simulate` would run, instead of running it (the command then ends as
    if interrupted: exit code 130)."""
    seen: list[ScenarioConfig] = []

    def capture(resolved, progress=None):
        seen.append(resolved.config)  # the command resolves the scenario once
        raise KeyboardInterrupt

    monkeypatch.setattr("geovs_drake.cli.simulate.simulate", capture)
    return seen


def test_layers_file_then_scenario_text_then_flags(tmp_path, run_cli, loaded):
    path = tmp_path / "scenario.yaml"
    path.write_text(
        "plant: kinematic\nduration: 7\ncontrol: {kinematic_gain: 3, potential_gain: 5}\n"
        "initial: {xyz: [0.1, 0, -0.7], rpy: [0, 0, 1]}\n"
    )
    text = "{duration: 9, control: {kinematic_gain: 2}, initial: {xyz: [0, 0.05, -0.6]}}"
    run = run_cli(
        "simulate", "--config", str(path), "--scenario-text", text, "--duration", "11",
        "--ibvs-depth", "mean", "--controller", "ibvs",
    )  # fmt: skip
    assert run.code == cli.EXIT_INTERRUPTED, run.err
    (config,) = loaded
    assert config.plant == Kinematic()  # the file's
    assert config.control.potential_gain == 5  # the file's: mappings merge key by key
    assert config.control.kinematic_gain == 2  # the text over the file
    assert config.duration == 11  # the flag over the text and the file
    assert config.controller == Ibvs(depth="mean")  # a law's flag on the law the flags chose
    # The text's pose is whole: its rpy is zero, not the file's nor the default's.
    assert config.initial == PoseConfig(xyz=[0.0, 0.05, -0.6], rpy=[0.0, 0.0, 0.0])


def test_scenario_text_alone_runs(run_cli):
    run = run_cli(
        "simulate", "--scenario-text", "{plant: kinematic, control: {kinematic_gain: 2}}",
        "--duration", "12",
    )  # fmt: skip
    assert run.code == 0, run.err
    assert run.out.startswith("nf on the kinematic plant: converged")


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("{plant: [kinematic", ["--scenario-text: malformed YAML", "line 1"]),
        ("{colour: red}", ["--scenario-text: colour: unknown field"]),
        ("{control: {damping: 3}}", ["--scenario-text: control.damping: expected a list"]),
        ("[1, 2]", ["--scenario-text: expected a mapping"]),
        ("{plant: wheeled}", ["plant must be one of", "'wheeled'"]),
    ],
    ids=["malformed", "unknown-field", "wrong-type", "not-a-mapping", "bad-value"],
)
def test_bad_scenario_text_exits_2_with_one_line(text, needles, run_cli, loaded):
    run = run_cli("simulate", "--scenario-text", text)
    assert run.code == 2 and run.out == "" and not loaded
    _assert_one_line_error(run.err, *needles)


def test_every_scenario_flag_shows_the_dataclass_default(run_cli, loaded, capsys):
    """Each default that `simulate --help` shows, given back to its flag, is the default
    scenario: the help reads the dataclasses, and says so for every scenario flag."""
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    entries = _option_entries(capsys.readouterr().out)
    shown = {}
    for name, entry in entries.items():
        found = re.search(r"\(default: the config's, else (?:at rest )?(\S+)\)$", entry)
        if found:
            shown[name.split()[0]] = found.group(1)
    plain = {"-h", "--config", "--scenario-text", "--json"}
    assert set(shown) == set(entries) - plain  # every other flag sets a scenario field
    for flag, value in shown.items():
        loaded.clear()
        # A variant's flag (``with --controller NAME: ...``, ``with --carrier arm: ...``,
        # ``with --sensor pinhole|rendered: ...``) goes with its variant (the first named),
        # whose defaults it shows.
        variant = re.search(
            r"with --(controller|carrier|sensor) (\w+)",
            entries[next(e for e in entries if e.split()[0] == flag)],
        )
        argv = [f"--{variant.group(1)}", variant.group(2)] if variant else []
        run = run_cli("simulate", *argv, f"{flag}={value}")
        assert run.code == cli.EXIT_INTERRUPTED, (flag, run.err)
        expected = (
            ScenarioConfig(**{variant.group(1): AXES[variant.group(1)][variant.group(2)]()})
            if variant
            else ScenarioConfig()
        )
        # Resolved, as the command runs it (the arm's gain_scale applied to the gains).
        # As YAML: Drake's SimulatorConfig compares by identity.
        assert [yaml_dump_typed(c) for c in loaded] == [
            yaml_dump_typed(resolve(expected).config)
        ], flag


# ------------------------------------------------- robustness and camera-accuracy
@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["--starts", "0"], ["--starts must be >= 1", "0"]),
        (["--workers", "0"], ["--workers must be >= 1"]),
        (["--duration", "nan"], ["--duration must be finite and > 0", "nan"]),
        (["--soft-duration=-1"], ["--soft-duration must be finite and >= 0", "-1"]),
        (["--shrink", "1.5"], ["--shrink must be in (0, 1]", "1.5"]),
        (["--only", "gravity"], ["invalid choice", "gravity"]),
        (["--scenario-text", "{colour: red}"], ["--scenario-text: colour: unknown field"]),
        (["--config", "missing.yaml"], ["missing.yaml: no such file"]),
    ],
    ids=["starts", "workers", "duration", "soft-duration", "shrink", "only", "text", "config"],
)
def test_robustness_bad_input_exits_2_with_one_line_and_writes_nothing(
    argv, needles, tmp_path, monkeypatch, run_cli
):
    monkeypatch.chdir(tmp_path)
    run = run_cli("robustness", "--out", str(tmp_path / "r"), *argv)
    assert run.code == 2 and run.out == ""
    _assert_one_line_error(run.err, *needles)
    assert list(tmp_path.iterdir()) == []


def test_robustness_out_a_file_exits_2(tmp_path, run_cli):
    target = tmp_path / "file"
    target.write_text("")
    run = run_cli("robustness", "--out", str(target))
    assert run.code == 2
    _assert_one_line_error(run.err, "--out", "not a directory")


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["--poses", "0"], ["--poses must be >= 1"]),
        (["--resolution", "8x8"], ["expected WxH"]),
        (["--scenario-text", "{plant: [1"], ["--scenario-text: malformed YAML"]),
    ],
    ids=["poses", "resolution", "text"],
)
def test_camera_accuracy_bad_input_exits_2_with_one_line(argv, needles, run_cli):
    run = run_cli("camera-accuracy", *argv)
    assert run.code == 2 and run.out == ""
    _assert_one_line_error(run.err, *needles)


def test_python_m_geovs_drake_cli_is_the_command(run_cli):
    run = run_cli("--version", subprocess=True)
    assert run.code == 0 and run.out.startswith("geovs-drake ")


def test_the_command_line_starts_without_the_loop():
    """--help, --version and bad input answer before the loop, the systems or the sweep
    are imported (each command imports what it runs when it runs it)."""
    import subprocess

    heavy = (
        "geovs_drake.simulation", "geovs_drake.loop", "geovs_drake.systems", "geovs_drake.batch",
        "geovs_drake.analysis.sweep", "geovs_drake.analysis.studies.robustness",
    )  # fmt: skip
    code = (
        "import sys, geovs_drake.cli as c; c.build_parser(); "
        f"print(sorted(m for m in sys.modules if m.startswith({heavy!r}) "
        "and m != 'geovs_drake.analysis.studies.robustness_levels'))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", done.stdout


# ------------------------------------- one option per axis, generated from AXES (issue 41)
def test_each_axis_has_one_option_whose_choices_are_its_variants(monkeypatch):
    """`simulate`'s --carrier, --plant, --sensor, --controller are made from AXES: every
    variant is a choice (--carrier offered free|arm, the fixed camera only as --mount
    fixed), and a variant added to an axis is a choice with no edit of the command line."""
    import dataclasses

    from geovs_drake.cli._options import VALUE_AXES

    options = _visible_options(cli.subcommands()["simulate"])
    for axis, variants in AXES.items():
        flags = VALUE_AXES.get(axis, (f"--{axis}",))
        assert all(flag in options for flag in flags), axis
        if axis not in VALUE_AXES:
            assert options[f"--{axis}"] == tuple(variants), axis

    @dataclasses.dataclass
    class Gantry:
        """A gantry. It carries the camera on rails."""

    monkeypatch.setitem(AXES, "carrier", {**AXES["carrier"], "gantry": Gantry})
    help_text = cli.help_text("simulate")
    assert f"--carrier {{{','.join([*AXES['carrier']])}}}" in help_text
    assert "gantry: A gantry" in " ".join(help_text.split())  # its docstring's first sentence


def test_carrier_fixed_is_the_file_s_spelling_and_mount_points_to_it(tmp_path, run_cli, loaded):
    """--carrier fixed is `carrier: fixed` of a file; --mount fixed, the
    earlier spelling, runs the same scenario with one line pointing to it."""
    path = tmp_path / "fixed.yaml"
    path.write_text("carrier: fixed\n")
    runs = {
        "file": run_cli("simulate", "--config", str(path)),
        "flag": run_cli("simulate", "--carrier", "fixed"),
        "mount": run_cli("simulate", "--mount", "fixed"),
    }
    assert all(run.code == cli.EXIT_INTERRUPTED for run in runs.values()), runs
    assert [type(c.carrier).__name__ for c in loaded] == ["FixedCamera"] * 3
    assert yaml_dump_typed(loaded[0]) == yaml_dump_typed(loaded[1]) == yaml_dump_typed(loaded[2])
    assert runs["flag"].err.splitlines() == ["geovs-drake: interrupted"]
    assert runs["mount"].err.splitlines()[0] == (
        "geovs-drake: warning: --mount fixed is deprecated: write --carrier fixed"
    )
    assert "--mount" not in cli.help_text("simulate")  # deprecated: out of --help


# -------------------------------------------------- --latency-frames (issue 42)
@pytest.mark.parametrize("command", ["simulate", "sweep", "station", "controller"])
def test_latency_frames_sets_the_camera_s_latency(command):
    """--latency-frames N is the camera sensor's latency_frames, as the scenario's
    `sensor: !Pinhole {latency_frames: N}` says it; every other field as without it."""
    from geovs_drake.cli._options import load_layers
    from geovs_drake.cli.station import setup_of

    def config_of(*argv: str) -> ScenarioConfig:
        args = cli.build_parser().parse_args([command, *argv])
        if command in ("station", "controller"):  # the station file, the panda's
            return setup_of(args).resolved.config
        return load_layers(args)

    given = config_of("--sensor", "pinhole", "--latency-frames", "2")
    written = config_of("--scenario-text", "sensor: !Pinhole {latency_frames: 2}")
    assert given.sensor.latency_frames == 2
    assert yaml_dump_typed(given) == yaml_dump_typed(written)


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["--latency-frames", "1"], ["--latency-frames", "exact", "add --sensor pinhole"]),
        (["--sensor", "pinhole", "--latency-frames=-1"], ["frames >= 0", "'-1'"]),
        (["--sensor", "pinhole", "--latency-frames", "0.5"], ["frames >= 0", "'0.5'"]),
        (["--carrier", "fixed_camera"], ["--carrier", "'fixed_camera'", "fixed"]),
    ],
    ids=["exact-sensor", "negative", "fraction", "carrier"],
)
def test_the_new_options_refuse_bad_input_in_one_line(argv, needles, run_cli, loaded):
    for command in ("simulate", "sweep") if argv[0] != "--carrier" else ("simulate",):
        run = run_cli(command, *argv)
        assert run.code == 2 and run.out == "", (command, run.err)
        _assert_one_line_error(run.err, *needles)
    assert loaded == []


def test_an_untagged_sensor_with_a_camera_s_field_names_the_tag_to_write(run_cli):
    """`sensor: {latency_frames: 1}` reads as !Exact, which has no latency: the one line
    writes the variant that has it, and that spelling loads."""
    run = run_cli("simulate", "--scenario-text", "sensor: {latency_frames: 1}")
    assert run.code == 2
    _assert_one_line_error(run.err, "tagged variant", "write sensor: !Pinhole {latency_frames: 1}")
    written = run.err.split("write sensor: ")[1].strip()
    assert load_scenario(data=f"sensor: {written}").sensor == Pinhole(latency_frames=1)


def test_no_command_line_function_is_over_100_lines():
    """A command's options in groups (simulate's add_parser was 240 lines): each
    function of geovs_drake/cli, as written, at most 100 lines."""
    import ast

    long = []
    for path in sorted((ROOT / "geovs_drake" / "cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > 100:
                    long.append(f"{path.name}:{node.name} {lines}")
    assert long == []

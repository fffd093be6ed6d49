"""The command line's contract: exit codes, one-line errors for bad input, --version, help."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from geovs_drake import cli
from geovs_drake.cli import EXIT_CODES, main
from geovs_drake.simulation import SimulationResult


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


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
    "inertia-two": ("rig:\n  inertia_diagonal: [0.02, 0.02]\n", ["rig.inertia_diagonal", "3"]),
    "inertia-zero": ("rig:\n  inertia_diagonal: [0.02, 0, 0.02]\n", ["rig.inertia_diagonal"]),
    "root-a-list": ("- 1\n- 2\n", ["expected a mapping"]),
}


@pytest.mark.parametrize("name", list(BAD_CONFIGS))
def test_simulate_bad_config_exits_2_with_one_line(name, tmp_path, capsys):
    text, needles = BAD_CONFIGS[name]
    path = tmp_path / "scenario.yaml"
    path.write_text(text)
    code, out, err = _run(["simulate", "--config", str(path)], capsys)
    assert code == 2, err
    assert out == ""
    _assert_one_line_error(err, *needles)


def test_simulate_missing_config_exits_2_with_one_line(tmp_path, capsys):
    missing = tmp_path / "nope.yaml"
    code, out, err = _run(["simulate", "--config", str(missing)], capsys)
    assert code == 2 and out == ""
    _assert_one_line_error(err, str(missing), "no such file")


def test_simulate_good_config_overridden_by_options(tmp_path, capsys):
    path = tmp_path / "scenario.yaml"
    path.write_text("plant: kinematic\nduration: 0\nsimulator:\n  accuracy: 1e-6\n")
    # The file's bad duration is overridden by --duration: the run goes ahead.
    code, out, err = _run(["simulate", "--config", str(path), "--duration", "12"], capsys)
    assert code == 0, err
    assert out.startswith("nf on the kinematic plant: converged")


def test_simulate_exit_0_when_converged(capsys):
    code, out, err = _run(["simulate", "--plant", "kinematic", "--duration", "12"], capsys)
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
def test_simulate_exit_3_when_it_ran_and_did_not_converge(argv, status, capsys):
    code, out, err = _run(["simulate", *argv], capsys)
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


def test_simulate_exit_130_when_interrupted(monkeypatch, capsys):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("geovs_drake.cli.simulate.simulate", interrupted)
    code, out, err = _run(["simulate", "--duration", "1"], capsys)
    assert code == 130
    _assert_one_line_error(err, "interrupted")


def test_demo_exit_3_when_the_run_did_not_converge(monkeypatch, tmp_path, capsys):
    import geovs_drake.demo

    class _Result:
        status = "left_domain"

    def fake_run_demo(
        out: str, duration: float | None, meshcat: bool, rendered: bool = True
    ) -> SimulationResult:
        return _Result()  # type: ignore[return-value]

    monkeypatch.setattr(geovs_drake.demo, "run_demo", fake_run_demo)
    code, _, err = _run(["demo", "--out", str(tmp_path / "d"), "--duration", "1"], capsys)
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
def test_demo_bad_duration_exits_2_and_creates_nothing(argv, needles, tmp_path, capsys):
    out_dir = tmp_path / "x"
    code, out, err = _run(["demo", "--out", str(out_dir), *argv], capsys)
    assert code == 2 and out == ""
    _assert_one_line_error(err, *needles)
    assert not out_dir.exists()
    assert list(tmp_path.iterdir()) == []


def test_demo_out_an_existing_file_exits_2(tmp_path, capsys):
    target = tmp_path / "results"
    target.write_text("not a folder")
    code, _, err = _run(["demo", "--out", str(target), "--duration", "1"], capsys)
    assert code == 2
    _assert_one_line_error(err, "--out", str(target), "not a directory")
    assert target.read_text() == "not a folder"


def test_demo_out_under_a_file_exits_2(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    code, _, err = _run(["demo", "--out", str(blocker / "x"), "--duration", "1"], capsys)
    assert code == 2
    _assert_one_line_error(err, "--out", str(blocker), "not a directory")
    assert sorted(tmp_path.iterdir()) == [blocker]


def test_demo_out_under_a_read_only_folder_exits_2(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if _can_write(locked):
            pytest.skip("running as a user who can write anywhere (root)")
        code, _, err = _run(["demo", "--out", str(locked / "x"), "--duration", "1"], capsys)
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

    p = Progress(30, "%", "dynamic servo", min_interval_s=3600.0)
    for done in (5, 7, 12, 12, 29, 30):
        p.update_to(done)
    p.close()
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = err.strip().splitlines()
    assert lines[0].startswith("dynamic servo: 5/30 %") and lines[-1].startswith(
        "dynamic servo: 30/30 %"
    )
    assert len(lines) == 2  # the first, then nothing for an hour but the last


def test_demo_progress_is_sparse_in_a_log(tmp_path):
    """`demo` with stderr to a file (not a TTY): plain progress lines, no tqdm bar."""
    out = tmp_path / "demo"
    run = subprocess.run(
        [sys.executable, "-m", "geovs_drake.cli", "demo", "--out", str(out), "--duration", "2",
         "--no-meshcat", "--no-rendered"],
        capture_output=True,
        text=True,
    )  # fmt: skip
    assert run.returncode == cli.EXIT_NOT_CONVERGED, run.stderr  # 2 s is too short
    assert "\r" not in run.stderr
    assert "dynamic servo: 100/100 %" in run.stderr


def test_progress_waits_for_its_delay_and_stays_quiet_on_short_work(monkeypatch, capsys):
    """delay_s: nothing before it (a short run prints nothing at all), then sparse lines."""
    from geovs_drake import progress as progress_module

    clock = {"now": 100.0}
    monkeypatch.setattr(progress_module.time, "perf_counter", lambda: clock["now"])

    def run(steps: list[tuple[float, int]]) -> list[str]:
        clock["now"] = 100.0
        p = progress_module.Progress(100, "%", "geovs-drake simulate", delay_s=3.0)
        for t, done in steps:
            clock["now"] = 100.0 + t
            p.update_to(done)
        p.close()
        return capsys.readouterr().err.splitlines()

    assert run([(0.1, 10), (1.0, 60), (2.9, 100)]) == []  # done within the delay: quiet
    lines = run([(1.0, 10), (2.9, 50), (3.1, 60), (4.0, 70), (5.2, 80), (5.3, 100)])
    assert lines == [
        "geovs-drake simulate: 60/100 % after 3.1 s",  # the first after the delay
        "geovs-drake simulate: 80/100 % after 5.2 s",  # min_interval_s = 2 later
        "geovs-drake simulate: 100/100 % after 5.3 s",  # and always the end
    ]


def test_simulate_progress_goes_to_stderr_and_changes_nothing_else(monkeypatch, capsys):
    """`simulate --json` off a terminal: progress lines on stderr only past the delay; stdout
    is the same one JSON line, and the run the same, steps included."""
    import json
    import re

    argv = ["simulate", "--json", "--duration", "5"]
    code, out_quiet, err_quiet = _run(argv, capsys)
    assert err_quiet == ""  # well under SIMULATE_PROGRESS_DELAY_S: no progress at all
    monkeypatch.setattr(cli, "SIMULATE_PROGRESS_DELAY_S", 0.0)
    code_shown, out, err = _run(argv, capsys)
    assert code_shown == code
    lines = err.splitlines()
    assert 2 <= len(lines) <= 3 and "\r" not in err, err  # first, (maybe one more), last
    assert all(re.fullmatch(r"geovs-drake simulate: \d+/100 % after \d+\.\d s", x) for x in lines)
    assert lines[-1].startswith("geovs-drake simulate: 100/100 %")
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


def test_readme_synopsis_names_real_options_and_their_choices(capsys):
    """Each `[--option a|b|c]` of the README's command-line synopsis is an option of that
    command with exactly those choices (e.g. sweep's --velocity lists `above` too).
    --plant and --controller are left to the plant/controller work, which extends them."""
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    synopsis = readme.split("## Command line")[1].split("```")[1]
    commands = re.split(r"^geovs-drake ", synopsis, flags=re.M)[1:]
    checked = 0
    for block in commands:
        command = block.split()[0]
        if command.startswith("--"):
            continue
        with pytest.raises(SystemExit):
            main([command, "--help"])
        usage = capsys.readouterr().out.split("\n\n")[0]
        for option, arg in re.findall(r"\[(--[\w-]+)(?: ([^\]]+))?\]", block):
            assert re.search(rf"\[{option}[ \]]", usage), (command, option)
            if "|" in arg and option not in ("--plant", "--controller"):
                choices = re.search(rf"\[{option} \{{([^}}]+)\}}\]", usage).group(1).split(",")
                assert sorted(arg.split("|")) == sorted(choices), (command, option)
                checked += 1
    assert checked >= 2  # sweep's --velocity and --engine at least


def test_a_closed_pipe_ends_quietly_with_its_own_exit_code():
    """`geovs-drake ... | head` closes stdout early: no traceback, exit code 141."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "geovs_drake.cli", "simulate", "--json", "--duration", "0.2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    proc.stdout.close()  # the reader is gone before the result is written
    err = proc.stderr.read()
    assert proc.wait() == 141, err
    assert "Traceback" not in err and "BrokenPipeError" not in err, err

"""What the tests share.

* The one CLI runner: ``run_cli(*argv)`` runs ``geovs-drake`` in this process (``main``,
  argparse's own exits caught), ``run_cli(*argv, subprocess=True)`` through
  ``python -m geovs_drake.cli``; both give the exit code, stdout and stderr.
* The scenarios the tests build on, each a fresh copy to vary: ``default_config``, and
  the default with one axis changed, ``kinematic_config`` (``plant=Kinematic()``),
  ``pinhole_config`` (``sensor=Pinhole()``), ``fixed_camera_config``
  (``carrier=FixedCamera()``) and ``arm_config`` (``carrier=Arm()``).
* ``lcm_url(transport)``: an LCM bus for the hardware tests, ``memq://`` in this process
  or a UDP multicast URL on a port nothing is bound to (``ttl=0``: this machine only).
"""

from __future__ import annotations

import random
import socket
import subprocess as _subprocess
import sys
from collections.abc import Callable
from typing import NamedTuple

import pytest

from geovs_drake.scenario import Arm, FixedCamera, Kinematic, Pinhole, ScenarioConfig

#: The multicast group the UDP buses use (LCM's default) and the range their ports are
#: drawn from.
LCM_GROUP, LCM_PORT_RANGE = "239.255.76.67", (20000, 60000)


def _free_udp_port() -> int:
    """A UDP port in LCM_PORT_RANGE that nothing is bound to (a bind without SO_REUSEADDR
    fails where an LCM socket, which sets it, already listens)."""
    rng = random.Random()
    for _ in range(100):
        port = rng.randint(*LCM_PORT_RANGE)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("", port))
            except OSError:
                continue
        return port
    raise RuntimeError(f"no free UDP port in {LCM_PORT_RANGE}")


@pytest.fixture
def lcm_url() -> Callable[[str], str]:
    """``lcm_url("memq")``: the in-process bus; ``lcm_url("udpm")``: a fresh UDP bus."""

    def url(transport: str) -> str:
        if transport == "memq":
            return "memq://"
        return f"udpm://{LCM_GROUP}:{_free_udp_port()}?ttl=0"

    return url


@pytest.fixture
def default_config() -> ScenarioConfig:
    """The default scenario: the free rig, dynamic, the exact sensor, the NF."""
    return ScenarioConfig()


@pytest.fixture
def kinematic_config() -> ScenarioConfig:
    """The default scenario on the kinematic plant (Eqs. 17-19)."""
    return ScenarioConfig(plant=Kinematic())


@pytest.fixture
def pinhole_config() -> ScenarioConfig:
    """The default scenario seen through the pinhole camera at 30 Hz."""
    return ScenarioConfig(sensor=Pinhole())


@pytest.fixture
def fixed_camera_config() -> ScenarioConfig:
    """The default scenario with the camera fixed and the target driven (eye-to-hand)."""
    return ScenarioConfig(carrier=FixedCamera())


@pytest.fixture
def arm_config() -> ScenarioConfig:
    """The default scenario on the default arm (the shipped UR5), dynamic."""
    return ScenarioConfig(carrier=Arm())


class CliRun(NamedTuple):
    """What one ``geovs-drake`` command did."""

    code: int
    out: str
    err: str


@pytest.fixture
def run_cli(capsys: pytest.CaptureFixture[str]) -> Callable[..., CliRun]:
    from geovs_drake.cli import main

    def run(*argv: str, subprocess: bool = False) -> CliRun:
        if subprocess:
            done = _subprocess.run(
                [sys.executable, "-m", "geovs_drake.cli", *argv], capture_output=True, text=True
            )
            return CliRun(done.returncode, done.stdout, done.stderr)
        capsys.readouterr()  # only this command's output
        try:
            code = main(list(argv))
        except SystemExit as e:  # argparse's own errors, --help, --version
            code = e.code
        out, err = capsys.readouterr()
        return CliRun(code, out, err)

    return run


#: The files whose tests run the arm's compiled batch kernels: last, since make test
#: starts pytest while the warm-up's arm half still compiles them (about 45 s of CPU on a
#: fresh clone), so that they find them in the cache rather than compile them again.
ARM_KERNEL_FILES = (
    "test_arm_tree.py", "test_batch_arm.py", "test_batch_arm_pinhole.py", "test_arm_start_ik.py",
)  # fmt: skip


#: Items that run longest, started first so that pytest-xdist's workers finish together
#: (longest first): the wheel check, then the notebooks; the arm's batch kernels' last.
def _start_order(item: pytest.Item) -> int:
    if item.get_closest_marker("wheel") is not None:
        return 0
    if item.nodeid.endswith(".ipynb") or ".ipynb::" in item.nodeid:
        return 1
    if item.nodeid.split("::")[0].endswith(ARM_KERNEL_FILES):
        return 3
    return 2


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Longest first (:func:`_start_order`), the rest in their usual order, the arm's
    batch kernels' tests last."""
    items.sort(key=_start_order)  # a stable sort: each group keeps its order

"""The Panda over LCM as two processes (issue 34): ``geovs-drake station`` and
``geovs-drake controller`` as subprocesses on UDP multicast (a free port, ``ttl=0``),
in real time, from the issue's small move. The truth is the station's JSON (its
plant's ground truth); this process also listens on the bus and counts the commands.

(a) A 30 s run converges with more than 1000 commands received (a 0.5 s command
    timeout: the 2 shared cores starve a process now and then).
    The controller, outliving the station, ends ``station_stopped`` (exit 0): its
    statuses stopped after its own estimate had converged.
(b) The controller killed (SIGKILL) mid-run: the station ends ``command_lost`` and the
    held arm's joint speed falls below 0.01 rad/s within the command timeout plus the
    hold time.
(c) A pinhole camera with ``latency_frames: 1`` on both sides (its frames stamped with
    their capture, issue 42): the pair converges from the small move and from a start
    on the other side of the goal, the controller ending ``station_stopped``.

All slow (each is a real-time run): ``pytest -m slow tests/test_hardware_two_process.py``.
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import os
import signal
import subprocess
import sys
import time

import pytest
from drake import lcmt_panda_command
from pydrake.lcm import DrakeLcm

from geovs_drake.hardware.config import HardwareConfig
from geovs_drake.hardware.run import SETTLED_JOINT_SPEED

try:
    importlib.metadata.distribution("example-robot-data")
except importlib.metadata.PackageNotFoundError:
    pytest.skip('the Panda needs example-robot-data: pip install "geovs-drake[panda]"',
                allow_module_level=True)  # fmt: skip

pytestmark = pytest.mark.slow

#: The issue's small move.
SMALL_MOVE = "--initial=0.05,-0.03,-0.55,0.1,-0.05,0.3"
#: The issue's must-show: a 30 s run, more than this many commands received.
RUN_S = 30.0
MIN_COMMANDS = 1000
#: The controller runs longer than the station: it starts first and stops once the
#: station's statuses end ("no status within the status timeout").
CONTROLLER_EXTRA_S = 15.0
#: How long [s, wall] the listener hears commands before it kills the controller (the
#: arm still moving at a few hundredths of a rad/s).
COMMANDING_BEFORE_KILL_S = 2.0
#: The convergence run's command timeout [s]: the shipped 0.1 s (drake-franka-driver's
#: expire_sec) is for a real-time host; this machine's 2 cores are shared with other
#: jobs, and a process starved of CPU for 0.1 s (seen once in seven runs, after
#: convergence) would end the run command_lost. The kill run keeps the shipped one.
CONVERGE_COMMAND_TIMEOUT_S = 0.5
#: One thread per process for the numeric libraries: the two processes have a core each.
SINGLE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                        "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}  # fmt: skip
#: How long [s] the test waits for either process beyond its run time.
SLACK_S = 60.0
#: Time [s] the listener waits for a message in one call.
POLL_MS = 50


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "geovs_drake.cli", *args]


def _start(args: list[str]) -> subprocess.Popen:
    env = {**os.environ, **SINGLE_THREAD}
    return subprocess.Popen(
        args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )


def _summary(process: subprocess.Popen, timeout: float) -> tuple[int, dict, str]:
    out, err = process.communicate(timeout=timeout)
    lines = out.strip().splitlines()
    return process.returncode, (json.loads(lines[-1]) if lines else {}), err


class BusListener:
    """This process's own view of the bus: the messages on each channel and when the
    first and last came [s, monotonic]; the commands decoded (a malformed one raises)."""

    def __init__(self, url: str) -> None:
        self.lcm = DrakeLcm(url)
        channels = HardwareConfig().channels
        self.command_channel = channels.command
        self.seen: dict[str, list[float]] = {}
        for channel in (channels.status, channels.command, channels.camera):
            self.seen[channel] = [0, math.nan, math.nan]
            self.lcm.Subscribe(channel, lambda data, c=channel: self._on_message(c, data))

    def _on_message(self, channel: str, data: bytes) -> None:
        if channel == self.command_channel:
            lcmt_panda_command.decode(data)
        now = time.monotonic()
        seen = self.seen[channel]
        seen[0] += 1
        seen[1] = now if seen[0] == 1 else seen[1]
        seen[2] = now

    @property
    def commands(self) -> int:
        return int(self.seen[self.command_channel][0])

    def commanding_for(self) -> float:
        """How long [s] commands have been heard (0 before the first)."""
        first = self.seen[self.command_channel][1]
        return 0.0 if math.isnan(first) else time.monotonic() - first

    def rates(self) -> dict[str, float]:
        """Messages per second on each channel, first to last."""
        return {c: (n - 1) / (last - first) if n > 1 else 0.0 for c, (n, first, last) in
                self.seen.items()}  # fmt: skip

    def pump_until(self, done, deadline: float) -> None:
        while not done() and time.monotonic() < deadline:
            self.lcm.HandleSubscriptions(POLL_MS)


def _run_pair(
    url: str,
    duration: float,
    kill_after: float | None = None,
    station_args: tuple = (),
    both_args: tuple = (),
    initial: str = SMALL_MOVE,
):
    """Controller, then station (``station_args`` added, ``both_args`` to both, from
    ``initial``), on the bus ``url`` (a fresh UDP port); the controller killed once
    commands have been heard for ``kill_after`` [s]; the station's and the controller's
    exit codes, JSON and stderr, this process's listener, and the wall time."""
    listener = BusListener(url)
    start = time.monotonic()
    deadline = start + duration + SLACK_S
    controller = _start(
        _cli("controller", "--lcm", url, "--duration", str(duration + CONTROLLER_EXTRA_S),
             "--json", *both_args)
    )  # fmt: skip
    station = _start(
        _cli("station", "--lcm", url, "--duration", str(duration), initial, "--json",
             *station_args, *both_args)
    )  # fmt: skip
    try:
        if kill_after is not None:
            listener.pump_until(lambda: listener.commanding_for() >= kill_after, deadline)
            controller.send_signal(signal.SIGKILL)
        listener.pump_until(lambda: station.poll() is not None, deadline)
        station_out = _summary(station, SLACK_S)
        controller_out = _summary(controller, SLACK_S)
    finally:
        for p in (station, controller):
            if p.poll() is None:
                p.kill()
    return station_out, controller_out, listener, time.monotonic() - start


def test_a_30_s_two_process_run_converges_in_real_time(lcm_url):
    (rc, station, err), (rc_c, controller, _err_c), listener, wall = _run_pair(
        lcm_url("udpm"), RUN_S, station_args=("--command-timeout", str(CONVERGE_COMMAND_TIMEOUT_S))
    )
    print(f"\nstation {station}\ncontroller {controller}")
    print(f"heard {listener.seen}, rates {listener.rates()} Hz, wall {wall:.1f} s")
    assert rc == 0 and station["status"] == "converged", (station, err)
    assert station["commands_received"] > MIN_COMMANDS
    assert station["command_timeouts"] == 0
    # The station kept real time, and the controller commanded all along.
    assert station["realtime_rate"] > 0.9
    assert listener.commands >= station["commands_received"] - 1
    assert controller["stop_reason"] in ("", "no status within the status timeout")
    # Outliving the station, whose run converged: the statuses stopped after the
    # controller's own estimate had converged, which is success (exit 0).
    assert rc_c == 0 and controller["status"] == "station_stopped", controller
    # The controller's own estimate agrees with the station's truth.
    assert controller["estimated_position_error_m"] == pytest.approx(
        station["final_position_error_m"], abs=1e-3
    )


def test_killing_the_controller_holds_the_arm_and_it_stops(lcm_url):
    (rc, station, err), (rc_c, _c, _e), listener, wall = _run_pair(
        lcm_url("udpm"), RUN_S, COMMANDING_BEFORE_KILL_S
    )
    print(f"\nstation {station}\nheard {listener.seen}, wall {wall:.1f} s")
    assert rc_c == -signal.SIGKILL
    assert station["status"] == "command_lost", (station, err)
    timeout, hold = HardwareConfig().command_timeout, HardwareConfig().hold_time
    # Commands came for seconds before the kill; the gate latched within the timeout
    # (one status period of slack: it checks at the status rate).
    assert station["last_command_s"] - station["first_command_s"] > 1.0
    assert 0 < station["lost_time_s"] - station["last_command_s"] <= timeout + 2e-3
    # The arm was moving when the hold began, and was stopped within timeout + hold.
    assert station["hold_start_joint_speed"] > SETTLED_JOINT_SPEED
    settled = station["hold_settle_time_s"]
    assert math.isfinite(settled)
    assert settled - station["last_command_s"] <= timeout + hold
    assert station["final_joint_speed"] < SETTLED_JOINT_SPEED


#: The latency run (issue 42): the pinhole camera a frame late on both sides, the
#: issue's 10 s, from the small move and from a start of this test's own, on the other
#: side of the goal (lockstep: 3.4e-6 m at 10 s; simulate: 2.8e-6 m).
LATENCY = ("--scenario-text", "sensor: !Pinhole {rate: 30.0, latency_frames: 1}")
LATENCY_RUN_S = 10.0
OTHER_START = "--initial=-0.06,0.04,-0.5,-0.1,0.08,-0.25"


@pytest.mark.parametrize("start", [SMALL_MOVE, OTHER_START])
def test_a_pinhole_a_frame_late_converges_between_two_processes(start, lcm_url):
    (rc, station, err), (rc_c, controller, err_c), listener, wall = _run_pair(
        lcm_url("udpm"),
        LATENCY_RUN_S,
        station_args=("--command-timeout", str(CONVERGE_COMMAND_TIMEOUT_S)),
        both_args=LATENCY,
        initial=start,
    )
    print(f"\nstation {station}\ncontroller {controller}\nwall {wall:.1f} s")
    assert rc == 0 and station["status"] == "converged", (station, err)
    assert station["command_timeouts"] == 0
    assert rc_c == 0 and controller["status"] == "station_stopped", (controller, err_c)
    # The latency from a frame's stamp to the first command from it is over the
    # histogram's last bin (19 ms; a frame is 33 ms) for all but the first frame (taken
    # at 0, sent at once to fill the latency line): the stamp is the capture, not the
    # send (before: 1 to 7 ms).
    histogram = controller["latency_histogram"]
    assert histogram[-1] >= sum(histogram) - 1, histogram

"""The hardware configuration: the LCM bus, its channels, the driver's mode and the
timeouts, as typed dataclasses loaded with Drake's ``yaml_load_typed`` and validated
once (:meth:`HardwareConfig.validate`: ValueError naming the field and its value).

A station file (``geovs_drake/scenarios/panda_lcm.yaml``) is a scenario, the fields of
:class:`~geovs_drake.scenario.ScenarioConfig`, plus one section of its own,
``hardware:``, the fields of :class:`HardwareConfig` (the pattern of Drake's
hardware_sim: a scenario of sub-configs). :func:`split_station_file` parts the two: the
scenario's fields go to :func:`~geovs_drake.scenario.load_scenario` as a layer, the
``hardware`` section to ``yaml_load_typed``.
"""

import ipaddress
import math
import urllib.parse
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from pydrake.common.yaml import yaml_load_typed

from geovs_drake.scenario import ScenarioConfig

__all__ = [
    "DEFAULT_LCM_URL",
    "HARDWARE_ARM",
    "HARDWARE_SECTION",
    "LCM_SCHEMES",
    "MODES",
    "ChannelsConfig",
    "HardwareConfig",
    "check_hardware_arm",
    "check_lcm_url",
    "check_still_target",
    "load_hardware",
    "split_station_file",
]

#: LCM's default bus (the ``lcm`` library's own default), with ``ttl=0``: multicast that
#: never leaves this machine. A real robot's network needs ``ttl=1``.
DEFAULT_LCM_URL = "udpm://239.255.76.67:7667?ttl=0"
#: The LCM providers a URL may name: ``memq`` (one process, a queue in memory) and
#: ``udpm`` (UDP multicast, between processes and machines).
LCM_SCHEMES = ("memq", "udpm")
#: The driver's control modes (drake-franka-driver's ``--control_mode``): what PANDA_COMMAND
#: carries, joint torques (the NF's Eq. 45 through J_C^T) or joint velocities (the
#: kinematic law's twist through J_C^+).
MODES: dict[str, str] = {
    "torque": "joint torques, gravity excluded (the robot compensates it, as the FCI does)",
    "velocity": "joint velocities, tracked by the robot's own joint controller",
}
#: The one arm the station and the controller drive: drake-franka-driver's channels
#: carry a Franka Panda's 7 joints.
HARDWARE_ARM = "panda"
#: The section of a station file that holds :class:`HardwareConfig`.
HARDWARE_SECTION = "hardware"
#: The largest UDP port number.
_MAX_PORT = 65535
#: The largest multicast time-to-live.
_MAX_TTL = 255


@dataclass
class ChannelsConfig:
    """The LCM channels: drake-franka-driver's two, and the camera's two.

    ``camera``: the pinhole sensor's ``lcmt_scope`` messages (``utime`` the capture
    time [us], ``value`` = y (13), then the sensor's ``[valid, code, lost]`` and the
    frame's index). ``image``: the rendered sensor's ``lcmt_image_array`` (one colour
    image, RGBA 8-bit, its header's ``utime`` the capture time). A channel carries one
    message type: why two.
    """

    status: str = "PANDA_STATUS"
    command: str = "PANDA_COMMAND"
    camera: str = "CAMERA_FEATURES"
    image: str = "CAMERA_IMAGE"


@dataclass
class HardwareConfig:
    """The LCM bus and the driver's settings.

    ``lcm_url``: the bus (:data:`DEFAULT_LCM_URL`; ``memq://`` in one process).
    ``mode``: :data:`MODES`. ``status_rate`` [Hz]: PANDA_STATUS from the station (the
    FCI's 1 kHz); ``command_rate`` [Hz]: PANDA_COMMAND from the controller.
    ``command_timeout`` [s]: after the first command, none for this long and the
    station holds the arm (drake-franka-driver's ``expire_sec``, 0.1).
    ``status_timeout`` and ``frame_timeout`` [s]: the controller stops commanding when
    the last status or frame is older than these. ``startup_timeout`` [s]: how long the
    controller waits for its first status and frame. ``hold_damping`` [N m s/rad]: the
    joint damping with which the station holds the arm once commands are lost;
    ``hold_time`` [s]: how long it holds before the run ends. ``velocity_gain``
    [N m s/rad]: the station's joint velocity tracking in velocity mode.
    ``real_time_rate``: the station's pacing (1 between processes, 0: as fast as it
    can, the in-process test). ``drop_every_frame``: the station does not publish every
    N-th camera frame (0: it publishes all), to measure what a lost frame does.
    ``status_delay`` [s]: the station's statuses report the joints as they were this
    long ago (whole status periods; 0: as they are), to measure what a late status
    does.

    ``command_rate`` is below ``status_rate`` by default: the controller's law in
    Python costs about 0.4 ms a command on this 2-core machine, too close to 1 ms for
    a real-time loop beside the station; the robot holds the last command between
    (drake-franka-driver until ``expire_sec``), and the law's time scale (seconds) is
    far above 4 ms.
    """

    lcm_url: str = DEFAULT_LCM_URL
    channels: ChannelsConfig = field(default_factory=ChannelsConfig)
    mode: str = "torque"
    status_rate: float = 1000.0
    command_rate: float = 250.0
    command_timeout: float = 0.1
    status_timeout: float = 0.1
    frame_timeout: float = 0.5
    startup_timeout: float = 10.0
    hold_damping: float = 10.0
    hold_time: float = 1.0
    velocity_gain: float = 20.0
    real_time_rate: float = 1.0
    drop_every_frame: int = 0
    status_delay: float = 0.0

    def validate(self) -> None:
        """ValueError naming the first bad field, ``hardware.<field>``, and its value."""
        check_lcm_url(self.lcm_url, "hardware.lcm_url")
        if self.mode not in MODES:
            raise ValueError(f"hardware.mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        for name in ("status", "command", "camera", "image"):
            channel = getattr(self.channels, name)
            if not (isinstance(channel, str) and channel.strip() == channel and channel):
                raise ValueError(
                    f"hardware.channels.{name} must be a non-empty name, got {channel!r}"
                )
        positive = ("status_rate", "command_rate", "command_timeout", "status_timeout")
        positive += ("frame_timeout", "startup_timeout", "velocity_gain")
        for name in positive:
            _check_number(f"hardware.{name}", getattr(self, name), strict=True)
        for name in ("hold_damping", "hold_time", "real_time_rate", "status_delay"):
            _check_number(f"hardware.{name}", getattr(self, name), strict=False)
        drop = self.drop_every_frame
        if not (isinstance(drop, int) and not isinstance(drop, bool) and drop >= 0):
            raise ValueError(f"hardware.drop_every_frame must be an integer >= 0: {drop!r}")
        if self.command_rate > self.status_rate:
            raise ValueError(
                f"hardware.command_rate must be <= status_rate ({self.status_rate}): "
                f"{self.command_rate!r}"
            )


def check_still_target(config: ScenarioConfig, part: str) -> None:
    """The station and the controller serve a still target: the LCM messages carry no
    target pose (nor its motion); ValueError in one line naming ``part`` otherwise."""
    if config.moving_target:
        raise ValueError(
            f"the {part}'s target stands still: target_motion must be !Still {{}} (a moving "
            f"target runs in `geovs-drake simulate`), got {type(config.target_motion).__name__}"
        )


def check_hardware_arm(config: ScenarioConfig, part: str) -> None:
    """The station and the controller drive :data:`HARDWARE_ARM` alone; ValueError in
    one line naming ``part`` and the scenario's carrier otherwise."""
    # Not a variant's type: any carrier without the arm's model field is refused too.
    model = getattr(config.carrier, "model", None)
    if model != HARDWARE_ARM:
        got = f"model {model!r}" if model is not None else type(config.carrier).__name__
        raise ValueError(
            f"the {part} drives the {HARDWARE_ARM} only (drake-franka-driver's channels): "
            f"carrier must be !Arm {{model: {HARDWARE_ARM}}}, got {got}"
        )


def _check_number(name: str, value: Any, strict: bool) -> None:
    real = isinstance(value, int | float) and not isinstance(value, bool)
    if not (real and math.isfinite(value) and (value > 0 if strict else value >= 0)):
        raise ValueError(f"{name} must be finite and {'>' if strict else '>='} 0: {value!r}")


def check_lcm_url(url: Any, name: str = "--lcm") -> None:
    """ValueError ``<name> <url>: <why>`` unless ``url`` is an LCM URL Drake can open:
    ``memq://``, or ``udpm://<multicast IPv4>:<port>[?ttl=N]``. Why here: DrakeLcm prints
    a bad URL's error and carries on with a dead bus, raising nothing."""
    if not isinstance(url, str):
        raise ValueError(f"{name} must be an LCM URL, got {url!r}")
    parts = urllib.parse.urlsplit(url)
    if parts.scheme not in LCM_SCHEMES or not url.startswith(parts.scheme + "://"):
        raise ValueError(
            f"{name} {url}: the provider must be one of {', '.join(s + '://' for s in LCM_SCHEMES)}"
        )
    if parts.scheme == "memq":
        return
    host, _, port = parts.netloc.partition(":")
    try:
        address = ipaddress.IPv4Address(host)
    except ValueError:
        raise ValueError(f"{name} {url}: {host!r} is not an IPv4 address") from None
    if not address.is_multicast:
        raise ValueError(f"{name} {url}: {host} is not a multicast address (224.0.0.0/4)")
    if not (port.isdigit() and 1 <= int(port) <= _MAX_PORT):
        raise ValueError(f"{name} {url}: the port must be 1 to {_MAX_PORT}, got {port!r}")
    for key, values in urllib.parse.parse_qs(parts.query, keep_blank_values=True).items():
        if key != "ttl":
            raise ValueError(f"{name} {url}: unknown option {key!r} (udpm takes ttl)")
        if not (values[-1].isdigit() and int(values[-1]) <= _MAX_TTL):
            raise ValueError(f"{name} {url}: ttl must be 0 to {_MAX_TTL}, got {values[-1]!r}")


def split_station_file(path: str | Path) -> tuple[dict, dict]:
    """A station file's scenario (its ScenarioConfig fields, tags kept, ready to be a
    :func:`~geovs_drake.scenario.load_scenario` layer) and its ``hardware`` section
    (a mapping; empty if the file has none). ValueError in one line naming the file."""
    # The scenario loader's own YAML reader: it keeps the variants' tags (!Arm {...}).
    from geovs_drake.scenario.load import load_tagged_yaml

    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: cannot read: {e}") from None
    try:
        tree = load_tagged_yaml(text)
    except yaml.YAMLError as e:
        raise ValueError(f"{path}: malformed YAML: {str(e).splitlines()[0]}") from None
    if tree is None:
        return {}, {}
    if not isinstance(tree, Mapping):
        raise ValueError(f"{path}: expected a mapping of fields, got {type(tree).__name__}")
    tree = dict(tree)
    hardware = tree.pop(HARDWARE_SECTION, None) or {}
    if not isinstance(hardware, Mapping):
        raise ValueError(f"{path}: {HARDWARE_SECTION} must be a mapping of fields")
    return tree, dict(hardware)


def load_hardware(
    section: Mapping[str, Any] | None = None, name: str = "hardware"
) -> HardwareConfig:
    """:class:`HardwareConfig` from a ``hardware`` section (a mapping; None: defaults),
    read by Drake's ``yaml_load_typed`` (unknown fields and wrong types refused) and
    validated. ValueError in one line starting ``name:`` for a field Drake refuses."""
    config = HardwareConfig()
    if section:
        try:
            config = yaml_load_typed(
                schema=HardwareConfig, data=yaml.safe_dump(dict(section)), defaults=config
            )
        except (RuntimeError, ValueError, TypeError, AssertionError) as e:
            lines = str(e).strip().splitlines() or [type(e).__name__]
            raise ValueError(f"{name}: {lines[0]}") from None
    config.validate()
    return config

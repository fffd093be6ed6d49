"""The scenario's typed variants (issue 30): each axis loads from its tag or its bare
name, the earlier flat spelling is refused in one line whose new spelling loads to what
the old file meant, a name in Python is refused, and the command line's flags map onto
the variants."""

import dataclasses

import pytest

from geovs_drake.scenario import (
    AXES,
    Arm,
    Dynamic,
    Exact,
    FixedCamera,
    FreeRig,
    Ibvs,
    Kinematic,
    Nf,
    Pinhole,
    PoseConfig,
    Rendered,
    ScenarioConfig,
    camera_like,
    load_scenario,
    variant_name,
)

#: An earlier, flat file, and the config it meant (as it ran before the variants).
EARLIER = [
    (
        "camera: {sensor: pinhole, rate: 15, latency_frames: 1}",
        ScenarioConfig(sensor=Pinhole(rate=15.0, latency_frames=1)),
    ),
    ("camera: {radius_error: 0.1}", ScenarioConfig(sensor=Exact(radius_error=0.1))),
    (
        "arm: {model: default, joint_damping: 1.5}\ncarrier: arm",
        ScenarioConfig(carrier=Arm(joint_damping=1.5)),
    ),
    ("rig: {mass: 2.0}", ScenarioConfig(carrier=FreeRig(mass=2.0))),
    ("rig: {mass: 2.0}\nmount: fixed", ScenarioConfig(carrier=FixedCamera(mass=2.0))),
    ("mount: fixed", ScenarioConfig(carrier=FixedCamera())),
    ("control: {ibvs_depth: mean}", ScenarioConfig(controller=Ibvs(depth="mean"))),
]


@pytest.mark.parametrize("old, meant", EARLIER, ids=[o.split(":")[0] for o, _ in EARLIER])
def test_the_earlier_spelling_is_refused_with_a_new_one_that_means_the_same(old, meant):
    with pytest.raises(ValueError) as error:
        load_scenario(data=old)
    message = str(error.value)
    assert "\n" not in message and "write " in message, message
    # The line's own suggestion, as a file: it loads to what the old file meant.
    key, new = message.split("write ", 1)[1].split(": ", 1)
    new = new.split(" (or ")[0]
    assert load_scenario(data=f"{key}: {new}") == meant, message


@pytest.mark.parametrize("axis", list(AXES))
def test_every_bare_name_reads_as_its_variant_with_its_defaults(axis):
    for name, kind in AXES[axis].items():
        loaded = getattr(load_scenario(data=f"{axis}: {name}"), axis)
        assert loaded == kind() and variant_name(loaded) == name
        tagged = getattr(load_scenario(data=f"{axis}: !{kind.__name__} {{}}"), axis)
        assert tagged == kind()


def test_an_untagged_mapping_is_the_unions_first_variant_as_drake_reads_it():
    config = load_scenario(data="carrier: {mass: 3.0}\nsensor: {radius_error: 0.05}")
    assert config.carrier == FreeRig(mass=3.0) and config.sensor == Exact(radius_error=0.05)


def test_a_field_of_another_variant_cannot_be_written():
    with pytest.raises(
        ValueError, match=r"sensor\.rate: unknown field \(known here: radius_error\)"
    ):
        load_scenario(data="sensor: !Exact {rate: 15}")
    with pytest.raises(ValueError, match=r"carrier\.model: unknown field"):
        load_scenario(data="carrier: !FreeRig {model: panda}")


def test_a_later_layer_edits_the_same_variant_and_replaces_another():
    base = "sensor: !Pinhole {rate: 15, latency_frames: 2}"
    same = load_scenario(data=base, overrides=["sensor: !Pinhole {pixel_noise: 0.5}"])
    assert same.sensor == Pinhole(rate=15.0, latency_frames=2, pixel_noise=0.5)
    other = load_scenario(data=base, overrides=["sensor: rendered"])
    assert other.sensor == Rendered()


@pytest.mark.parametrize(
    "axis, name, kind", [("plant", "kinematic", Kinematic), ("carrier", "arm", Arm)]
)
def test_a_name_in_python_is_one_line_naming_the_variant(axis, name, kind):
    config = ScenarioConfig(**{axis: name})
    with pytest.raises(ValueError) as error:
        config.validate()
    assert str(error.value) == (
        f"{axis} {name!r}: give the {axis} as its variant, {axis}={kind.__name__}() "
        f"(in YAML, {axis}: !{kind.__name__} {{}} or {axis}: {name})"
    )


def test_a_name_of_another_axis_says_which_axis_it_belongs_to():
    with pytest.raises(ValueError, match=r"controller 'kinematic' names a plant: write plant"):
        load_scenario(data="controller: kinematic")
    with pytest.raises(ValueError, match=r"sensor 'arm' names a carrier: write carrier: arm"):
        load_scenario(data="sensor: arm")


def test_camera_like_keeps_a_cameras_fields_across_models():
    pinhole = Pinhole(rate=20.0, pixel_noise=0.3, radius_error=0.1, damping=[1.0] * 6)
    rendered = camera_like(pinhole, Rendered, resolution=[640, 480])
    assert isinstance(rendered, Rendered)
    assert {f.name: getattr(rendered, f.name) for f in dataclasses.fields(Pinhole)} == {
        **dataclasses.asdict(pinhole),
        "resolution": [640, 480],
    }
    rendered.damping[0] = 9.0  # a copy: the source is untouched
    assert pinhole.damping[0] == 1.0
    assert camera_like(Exact(radius_error=0.2)) == Pinhole(radius_error=0.2)


def test_the_dynamic_fact_is_the_plants_type():
    assert ScenarioConfig().dynamic and not ScenarioConfig(plant=Kinematic()).dynamic
    assert Dynamic.gain_field == "potential_gain" and Kinematic.gain_field == "kinematic_gain"


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["--sensor", "pinhole", "--camera-rate", "15"], dict(sensor=Pinhole(rate=15.0))),
        (["--camera-rate", "15", "--sensor", "pinhole"], dict(sensor=Pinhole(rate=15.0))),
        (["--mount", "fixed"], dict(carrier=FixedCamera())),
        (
            ["--mount", "fixed", "--plant", "kinematic"],
            dict(carrier=FixedCamera(), plant=Kinematic()),
        ),
        (["--controller", "ibvs", "--ibvs-depth", "mean"], dict(controller=Ibvs(depth="mean"))),
        (
            ["--scenario-text", "sensor: !Pinhole {rate: 15, seed: 3}", "--sensor", "pinhole"],
            dict(sensor=Pinhole(rate=15.0, seed=3)),
        ),
        (["--controller", "nf"], dict(controller=Nf())),
    ],
)
def test_the_flags_map_onto_the_variants(argv, expected):
    from geovs_drake.cli import build_parser
    from geovs_drake.cli._options import load_config

    args = build_parser().parse_args(["simulate", *argv])
    config = load_config(args)
    for axis, value in expected.items():
        assert getattr(config, axis) == value, (argv, axis)


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["--camera-rate", "15"],
            "--camera-rate applies to --sensor pinhole|rendered, the sensor here is exact",
        ),
        (["--arm", "panda"], "--arm applies to --carrier arm, the carrier here is free"),
        (
            ["--joint-barrier", "0.5"],
            "--joint-barrier applies to --carrier arm, the carrier here is free",
        ),
        (
            ["--carrier", "arm", "--mount", "fixed"],
            "--mount fixed needs the free body (--carrier free)",
        ),
    ],
)
def test_a_variants_flag_under_another_variant_is_one_line_and_exit_2(run_cli, argv, message):
    run = run_cli("simulate", *argv, "--duration", "0.1")
    assert run.code == 2 and message in run.err and run.err.count("\n") == 1, run.err
    assert run.out == ""


def test_a_pose_under_a_carrier_is_whole():
    config = load_scenario(data="carrier: !FreeRig {camera_offset: {rpy: [0, 0, 1]}}")
    assert config.carrier.camera_offset == PoseConfig(xyz=[0.0, 0.0, 0.0], rpy=[0, 0, 1])

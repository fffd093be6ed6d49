"""A loop is carrier + sensor + law, composed by build_loop: every combination the README
lists converges on a small move; the combinations that make no sense are refused in one
line; every law believes the same radius, whatever carries the camera."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator

from geovs_drake.loop import CARRIERS, LAWS, SENSORS, build_loop, refusal, resolve
from geovs_drake.scenario import (
    CARRIER_VARIANTS,
    CONTROLLERS,
    LAW_VARIANTS,
    SENSOR_VARIANTS,
    Arm,
    Dynamic,
    Exact,
    FixedCamera,
    FreeRig,
    Kinematic,
    Pinhole,
    PoseConfig,
    Quadrotor,
    Rendered,
    ScenarioConfig,
    variant_name,
)
from geovs_drake.simulation import simulate

SMALL_MOVE = PoseConfig(xyz=[0.05, -0.03, -0.55], rpy=[0.1, -0.05, 0.3])

#: ``(carrier, plant)`` (the :data:`CARRIERS` key) with each sensor that can see through it.
CAMERA_CARRIERS = {(FreeRig, Dynamic)}
COMBINATIONS = [
    (carrier, sensor, law)
    for carrier in CARRIERS
    for sensor in SENSORS
    for law in CONTROLLERS
    if sensor is Exact or carrier in CAMERA_CARRIERS
    # A law that drives rotors (Hamel & Mahony's) on the carriers that have them only.
    if LAW_VARIANTS[law].traits.commands != "rotors" or carrier[0].traits.rotors
]


def _suite_case(carrier: tuple[type, type], sensor: type, law: str):
    """The combination as a test case: the long ones (a rendered camera, the arm with a
    twist law, a few seconds each) are marked slow, the arm keeping its NF case in the
    suite (make test-slow runs them all)."""
    # The rendered NF case too (5 s; make test's budget): test_rendered.py runs the rendered
    # loop against the pinhole one, and test_arm.py the rendered arm.
    # The quadrotor's twist laws too (2 s each): its NF case stays in the suite.
    long = sensor is Rendered or (carrier[0] in (Arm, Quadrotor) and law != "nf")
    name = "-".join([*(variant_name(kind()) for kind in (*carrier, sensor)), law])
    marks = [pytest.mark.slow] if long else []
    return pytest.param(carrier, sensor, law, marks=marks, id=name)


def _config(carrier: tuple[type, type], sensor: type, law: str, **changes) -> ScenarioConfig:
    kind, plant = carrier
    return ScenarioConfig(
        carrier=kind(),
        plant=plant(),
        sensor=sensor(),
        controller=LAW_VARIANTS[law](),
        initial=SMALL_MOVE,
        **changes,
    )


def test_the_registries_hold_every_part_the_scenario_names():
    """One registry per part, and the config's variants are exactly the registered ones."""
    assert set(LAWS) == set(LAW_VARIANTS.values()) and set(LAW_VARIANTS) == set(CONTROLLERS)
    assert set(SENSORS) == {Exact, Pinhole, Rendered}
    # Five laws everywhere, and Hamel & Mahony's on the quadrotor with the exact sensor.
    assert len(COMBINATIONS) == len(CARRIERS) * 5 + len(CAMERA_CARRIERS) * 2 * 5 + 1


@pytest.mark.parametrize(("carrier", "sensor", "law"), [_suite_case(*c) for c in COMBINATIONS])
def test_every_combination_builds_through_build_loop_and_converges(carrier, sensor, law):
    if sensor is Rendered:
        pytest.importorskip("cv2", reason="the rendered sensor needs the vision extra (OpenCV)")
    # 10 s through a camera (the frames' cost; each converges within it), 20 s otherwise.
    config = _config(carrier, sensor, law, duration=20.0 if sensor is Exact else 10.0)
    loop = build_loop(config, log=False)
    diagram = loop.diagram
    # The parts are in the diagram under their names, and the law acts on the sensor's y.
    assert diagram.HasSubsystemNamed("spherical_camera")
    assert (sensor is not Exact) == diagram.HasSubsystemNamed("feature_sensor")
    result = simulate(config)
    assert result.status == "converged", (carrier, sensor, law, result.message)


@pytest.mark.parametrize(
    ("changes", "sensor", "message"),
    [
        (
            dict(carrier="gantry"),
            "exact",
            # Every carrier's name, as CARRIER_VARIANTS spells it.
            f"carrier must be one of {', '.join(CARRIER_VARIANTS)}, got 'gantry'",
        ),
        (dict(controller="kinematic"), "exact", "names a plant: write plant: kinematic"),
        (dict(controller="lqr"), "exact", "controller must be one of nf, ibvs"),
    ],
)
def test_combinations_that_make_no_sense_are_refused_in_one_line(changes, sensor, message):
    config = ScenarioConfig(sensor=SENSOR_VARIANTS[sensor](), **changes)
    with pytest.raises(ValueError, match=message) as error:
        build_loop(config)
    assert len(str(error.value).splitlines()) == 1


def test_a_registry_without_the_part_is_named_in_one_line(monkeypatch):
    """A combination the config allows but no registered part carries: refusal() names it."""
    monkeypatch.delitem(CARRIERS, (FixedCamera, Kinematic))
    config = ScenarioConfig(carrier=FixedCamera(), plant=Kinematic())
    why = refusal(config)
    assert why.startswith(
        "carrier FixedCamera on plant Kinematic has no factory: "
        "register CARRIERS[FixedCamera, Kinematic] ("
    )
    assert "(FixedCamera, Kinematic)" not in why and len(why.splitlines()) == 1
    with pytest.raises(ValueError, match="carrier FixedCamera on plant Kinematic has no factory"):
        build_loop(config)


def _image_log(config: ScenarioConfig, horizon: float) -> np.ndarray:
    loop = build_loop(config, log=True)
    simulator = Simulator(loop.diagram)
    simulator.get_mutable_integrator().set_target_accuracy(1e-10)
    loop.carrier.set_initial_state(simulator.get_mutable_context())
    simulator.AdvanceTo(horizon)
    log = loop.diagram.GetSubsystemByName("log_image_features")
    return log.FindLog(simulator.get_context()).data()


def test_the_fixed_camera_believes_the_same_radius_as_the_hand_held_one():
    """With the controller's radius 20% off, the kinematic fixed-camera loop sees the
    same image y(t) as the eye-in-hand loop (Eq. 16: the laws see only the relative
    pose), to 1e-9. It did not while the fixed-camera builder handed the NF's
    kinematic law and force the true radius and y* the believed one."""
    config = ScenarioConfig(plant=Kinematic(), initial=SMALL_MOVE, log_rate=10.0)
    config.sensor.radius_error = 0.2
    config.simulator.integration_scheme = "runge_kutta5"
    hand = _image_log(config, 2.0)
    fixed = _image_log(dataclasses.replace(config, carrier=FixedCamera()), 2.0)
    np.testing.assert_allclose(fixed, hand, rtol=0, atol=1e-9)
    # The dynamic loops' force laws carry the same numbers (rho believed, k_p, B).
    dynamic = dataclasses.replace(config, plant=Dynamic())
    params = []
    for carrier in (FreeRig(), FixedCamera()):
        loop = build_loop(dataclasses.replace(dynamic, carrier=carrier), log=False)
        force = loop.diagram.GetSubsystemByName("image_jacobian_force")
        params.append(force.CreateDefaultContext().get_numeric_parameter(0).CopyToVector()[:8])
    np.testing.assert_array_equal(params[0], params[1])
    assert params[0][0] == pytest.approx(1.2 * config.radius)


def test_simulate_validates_a_scenario_once(monkeypatch):
    """Validation is at the edge: simulate() resolves once and the builder trusts it."""
    calls = []
    validate = ScenarioConfig.validate
    monkeypatch.setattr(ScenarioConfig, "validate", lambda self: calls.append(1) or validate(self))
    simulate(ScenarioConfig(initial=SMALL_MOVE, duration=0.5))
    assert len(calls) == 1


def test_the_damping_rule_is_resolved_in_one_place():
    """control.damping on the exact sensor, sensor.damping with a camera; the force law
    in the diagram carries the resolved one."""
    for sensor, expected in ((Exact(), "control"), (Pinhole(), "sensor")):
        config = ScenarioConfig(sensor=sensor)
        resolved = resolve(config)
        want = getattr(config, expected).damping
        assert list(resolved.damping) == want == config.damping
        force = build_loop(resolved, log=False).diagram.GetSubsystemByName("image_jacobian_force")
        damping = force.CreateDefaultContext().get_numeric_parameter(0).CopyToVector()[2:8]
        np.testing.assert_array_equal(damping, want)


def test_law_variants_load_from_yaml_and_the_earlier_form_names_the_new_one():
    """A law is its variant; a file's bare name reads as the variant with its defaults;
    the law's fields outside the law (the earlier global form) are one line that writes
    the new spelling; in Python a name is one line naming the variant."""
    from geovs_drake.scenario import Ibvs, PathFollowing, load_scenario

    tagged = load_scenario(data="controller: !Ibvs {depth: mean}\n")
    assert tagged.controller == Ibvs(depth="mean")
    assert load_scenario(data="controller: ibvs\n").controller == Ibvs()
    path = load_scenario(data="controller: !PathFollowing {duration: 3, feedback_gain: 0}\n")
    assert path.controller == PathFollowing(duration=3.0, feedback_gain=0.0)
    for text, needle in (
        ("controller: !Ibvs {depth: wrong}\n", "controller.depth must be one of"),
        ("controller: !Ibvs {dept: mean}\n", "controller.dept: unknown field"),
        ("controller: !Lqr {}\n", r"controller: expected a name \(nf, ibvs, .*got .*!Lqr"),
        (
            "controller: ibvs\ncontrol: {ibvs_depth: mean}\n",
            r"control.ibvs_depth: .* write controller: !Ibvs \{depth: mean\}",
        ),
        (
            "controller: path\npath: {duration: 5}\n",
            r"path: .* write controller: !PathFollowing \{duration: 5\}",
        ),
    ):
        with pytest.raises(ValueError, match=needle) as error:
            load_scenario(data=text).validate()
        assert len(str(error.value).splitlines()) == 1


def test_the_command_line_validates_a_scenario_once(monkeypatch, run_cli):
    """`geovs-drake simulate`: the file, --scenario-text and the flags are loaded as
    layers and validated once; simulate() and build_loop() trust the result."""
    calls = []
    validate = ScenarioConfig.validate
    monkeypatch.setattr(ScenarioConfig, "validate", lambda self: calls.append(1) or validate(self))
    code, out, _ = run_cli(
        "simulate",
        "--scenario-text",
        "{controller: !Pbvs {}}",
        "--initial=0.05,-0.03,-0.55,0.1,-0.05,0.3",
        "--duration",
        "0.5",
        "--json",
    )
    assert code in (0, 3) and '"controller": "pbvs"' in out
    assert len(calls) == 1


@pytest.mark.parametrize(
    ("plant", "carrier"),
    [(Dynamic(), FreeRig()), (Kinematic(), FreeRig()), (Dynamic(), FixedCamera())],
    ids=variant_name,
)
def test_poses_in_target_is_camera_pose_in_target_row_by_row(plant, carrier):
    """The batched X_BC of a run's states equals the one-state conversion of each row."""
    from geovs_drake.loop.state import camera_pose_in_target, initial_body_states, poses_in_target

    config = ScenarioConfig(plant=plant, carrier=carrier)
    rng = np.random.default_rng(3)
    X_BC = np.stack(
        [
            RigidTransform(
                RollPitchYaw(rng.uniform(-1, 1, 3)), rng.uniform(-1, 1, 3)
            ).GetAsMatrix4()
            for _ in range(5)
        ]
    )
    states = initial_body_states(config, X_BC)
    states[:, :4] *= 1.7  # an unnormalised quaternion, as an integrator leaves it
    batched = poses_in_target(config, states)
    for x, X in zip(states, batched, strict=True):
        one = camera_pose_in_target(config, x, config.dynamic).GetAsMatrix4()
        assert np.allclose(X, one, atol=1e-14)
    assert np.allclose(batched, X_BC, atol=1e-12)  # and both invert initial_body_states


def test_the_law_example_of_adding_a_part_runs_as_the_page_says():
    """docs/adding-a-part.rst's example, as written there: the variant, its system and its
    LAWS entry give a loop whose camera rolls at the rate about the optical axis (from
    the goal: X_BC(t) = X_BC* RotZ(rate t), the kinematic plant integrating exactly)."""
    from pathlib import Path

    from pydrake.math import RotationMatrix

    from geovs_drake.loop.laws import LAWS

    page = (Path(__file__).resolve().parents[1] / "docs" / "adding-a-part.rst").read_text()
    example = page.split("Example: a law of one's own")[1].split(".. code-block:: python")[1]
    code = "\n".join(
        line[4:] for line in example.splitlines() if line.startswith("    ") or not line.strip()
    )
    namespace: dict = {}
    before = dict(LAWS)
    try:
        exec(compile(code, "adding-a-part.rst", "exec"), namespace)
    finally:
        LAWS.clear()
        LAWS.update(before)
    result, config = namespace["result"], namespace["config"]
    assert result.summary()["controller"] == "ConstantRoll" and result.status == "not_converged"
    expected = config.X_BC_goal.rotation() @ RotationMatrix.MakeZRotation(0.5 * result.sim_time_s)
    np.testing.assert_allclose(result.final_X_BC.rotation().matrix(), expected.matrix(), atol=1e-6)

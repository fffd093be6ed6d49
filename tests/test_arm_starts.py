"""The sweep's arm starts by the compiled path (batch.arm_ik) against the plant's.

Truth: :func:`geovs_drake.goal.arm.goal_on_branch` stepped through MultibodyPlant's
context (``follow=None``, the code the sweep ran before): the compiled path must carry
the joints to the same goal joints (to 1e-9 rad) and so choose the same start branch, on
every start.
"""

import copy
import dataclasses

import numpy as np
import pytest
from pydrake.math import RigidTransform

from geovs_drake.analysis.sweep.parts import _ArmStarts
from geovs_drake.analysis.sweep.starts import sample_starts
from geovs_drake.batch import loop_parameters
from geovs_drake.goal.arm import Unreachable, chart_path, goal_on_branch, solve_joints
from geovs_drake.loop.resolved import exact_twin, free_twin
from geovs_drake.scenario import Arm, PoseConfig, ScenarioConfig

#: The compiled path's joints against the plant's [rad]: both Newton to rounding at the
#: goal, from steps that differ in their rounding alone.
JOINT_TOLERANCE = 1e-9


def _compare(model: str, n: int, whole: bool = True) -> int:
    """The first n sweep starts (seed 0, moving): the goal joints of both paths and, with
    ``whole``, the starts' joints and velocities of both (the plant's path once more);
    returns how many paths were compared."""
    config = ScenarioConfig(carrier=Arm(model=model))
    p = loop_parameters(exact_twin(free_twin(config)))
    X_BC, twists = sample_starts(config, n, 0, "bounded", 0, p)
    # Drake's IK in both (the compiled IK has its own test, test_arm_start_ik.py).
    fast = dataclasses.replace(_ArmStarts.of(config, p), solver=None)
    slow = dataclasses.replace(fast, follow=None)
    compared = 0
    for X, twist in zip(X_BC, twists, strict=True):
        c = copy.deepcopy(config)
        c.initial = PoseConfig.from_rigid_transform(RigidTransform(X))
        X_WC = c.X_WB @ RigidTransform(X)
        try:
            q = solve_joints(fast.model, X_WC)  # (cached: both paths start from it)
        except Unreachable:
            assert fast.joints(c, X, twist) is None
            continue
        path = chart_path(c, fast.domain, RigidTransform(X))
        if path is not None:
            a = goal_on_branch(fast.model, q, path, fast.follow)
            b = goal_on_branch(fast.model, q, path)
            assert (a is None) == (b is None)
            if a is not None:
                np.testing.assert_allclose(a, b, rtol=0, atol=JOINT_TOLERANCE)
                compared += 1
        if not whole:
            continue
        (q_fast, v_fast), (q_slow, v_slow) = fast.joints(c, X, twist), slow.joints(c, X, twist)
        np.testing.assert_allclose(q_fast, q_slow, rtol=0, atol=JOINT_TOLERANCE)
        assert (v_fast is None) == (v_slow is None)
        if v_fast is not None:
            np.testing.assert_allclose(v_fast, v_slow, rtol=0, atol=JOINT_TOLERANCE)
    return compared


def test_the_compiled_path_gives_the_plant_s_joints_on_ten_ur5_starts():
    """Ten UR5 starts (seven the arm reaches): the same goal joints."""
    assert _compare("default", 10, whole=False) >= 5


@pytest.mark.slow
@pytest.mark.parametrize("model", ["default", "panda"])
def test_the_compiled_path_gives_the_plant_s_joints_on_200_starts(model):
    """200 starts of each arm: the same goal joints, start branches and velocities."""
    assert _compare(model, 200) > 50

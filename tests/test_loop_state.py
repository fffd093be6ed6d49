"""The loop's initial states for a batch of camera poses against Drake's own
``RigidTransform`` composition and ``RotationMatrix::ToQuaternion``, start by start."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix

from geovs_drake.loop.state import initial_body_states
from geovs_drake.scenario import Dynamic, Kinematic, ScenarioConfig


def _poses(n: int) -> np.ndarray:
    """Random poses X_BC, with half turns about each axis and the identity among them:
    each of Shepperd's four branches (the trace, or one diagonal entry, the largest)."""
    rng = np.random.default_rng(7)
    quaternions = list(rng.normal(size=(n, 4)))
    quaternions += [np.eye(4)[k] for k in range(4)] + [np.array([1e-9, 1.0, 1.0, 0.0])]
    X = []
    for q in quaternions:
        R = RotationMatrix(Quaternion(q / np.linalg.norm(q)))
        X.append(RigidTransform(R, rng.normal(size=3)).GetAsMatrix4())
    return np.array(X)


@pytest.mark.parametrize("plant", [Dynamic(), Kinematic()], ids=["dynamic", "kinematic"])
def test_initial_states_of_a_batch_are_drakes_pose_by_pose(plant):
    config = ScenarioConfig(plant=plant)
    X_BC = _poses(300)
    states = initial_body_states(config, X_BC)
    X_RC = config.X_RC if config.dynamic else RigidTransform()
    for X, state in zip(X_BC, states, strict=True):
        X_W = config.X_WB @ RigidTransform(X) @ X_RC.inverse()
        np.testing.assert_allclose(state[:4], X_W.rotation().ToQuaternion().wxyz(), atol=1e-15)
        np.testing.assert_allclose(state[4:7], X_W.translation(), atol=1e-14)
        assert state[0] >= 0  # Drake's canonical sign

"""The quadrotor systems' flat kernels (systems/_quadrotor_kernels.py): the attitude
cascade's wrench against Lee, Leok & McClamroch's law written with Drake's rotations and
numpy, and the level view against the exact camera on the level body, each on floats
(the numba-compiled kernel) and on AutoDiffXd (the same Python, Linearize's path)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractValue, InitializeAutoDiff
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from geovs_drake.geometry.camera import camera_map
from geovs_drake.loop.carriers.quadrotor import rotor_layout
from geovs_drake.scenario import Quadrotor
from geovs_drake.systems._quadrotor_kernels import cascade as cascade_kernel
from geovs_drake.systems._quadrotor_kernels import for_scalar_type
from geovs_drake.systems.attitude_cascade import AttitudeCascade, mixer
from geovs_drake.systems.level_view import LevelView

#: The cascade's numbers (the Quadrotor's defaults but a heading off the x axis).
MASS, GRAVITY, INERTIA, GAINS = 0.775, 9.81, (0.0015, 0.0025, 0.0035), (3600.0, 108.0)
HEADING, DAMPING, MAX_TILT, MAX_THRUST = (0.8, 0.6, 0.0), 4.0, math.radians(10.0), 4.75


def _lee(x: np.ndarray, f_W: np.ndarray, tau_W: np.ndarray | None = None) -> np.ndarray:
    """(T, tau) of the cascade's docstring, by Drake's quaternion and numpy; with the NF's
    torque ``tau_W`` (heading ``nf``) x_d in the plane of z_d and the body's own x axis,
    and tau_z the NF's torque about z_B plus Euler's gyroscopic term about z_B."""
    R = RotationMatrix(Quaternion(x[0:4] / np.linalg.norm(x[0:4]))).matrix()
    heading = HEADING if tau_W is None else R[:, 0]
    Omega = R.T @ x[7:10]
    weight = MASS * GRAVITY
    f = f_W - DAMPING * x[10:13] + [0.0, 0.0, weight]
    up = max(f[2], 0.1 * weight)
    horizontal = np.linalg.norm(f[0:2])
    f = np.array([*(f[0:2] * min(1.0, math.tan(MAX_TILT) * up / horizontal)), up])
    z_d = f / np.linalg.norm(f)
    y_d = np.cross(z_d, heading)
    y_d /= np.linalg.norm(y_d)
    R_d = np.column_stack([np.cross(y_d, z_d), y_d, z_d])
    E = R_d.T @ R - R.T @ R_d
    e_R = 0.5 * np.array([E[2, 1], E[0, 2], E[1, 0]])
    J = np.diag(INERTIA)
    tau = J @ (-GAINS[0] * e_R - GAINS[1] * Omega) + np.cross(Omega, J @ Omega)
    if tau_W is not None:
        tau[2] = R[:, 2] @ tau_W + np.cross(Omega, J @ Omega)[2]
    return np.array([f @ R[:, 2], *tau])


def _states(rng: np.random.Generator, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Body states (13) and NF forces f_W (3): half near hover (within the limits), half
    tilted, turning and pushed hard (the tilt limit and the allocation's saturation)."""
    out = []
    for k in range(n):
        near = k % 2 == 0
        # Near hover: headed along HEADING (else the yaw alone saturates), tilted a little.
        rpy = rng.normal(0.0, 0.03 if near else 0.6, 3) + [0, 0, math.atan2(*HEADING[1::-1])]
        q = RollPitchYaw(rpy).ToQuaternion().wxyz()
        q *= rng.uniform(0.95, 1.05)  # off the unit sphere, as integrated
        rates = rng.normal(0.0, 0.1 if near else 4.0, 6)
        x = np.concatenate([q, rng.normal(0.0, 1.0, 3), rates])
        out.append((x, rng.normal(0.0, 0.3 if near else 8.0, 3)))
    return out


def _cascade(heading: str = "goal") -> AttitudeCascade:
    return AttitudeCascade(
        mass=MASS,
        inertia_diagonal=INERTIA,
        gravity=GRAVITY,
        attitude_gains=GAINS,
        heading_W=HEADING,
        mixer_matrix=mixer(*rotor_layout(Quadrotor())),
        max_thrust=MAX_THRUST,
        velocity_damping=DAMPING,
        max_tilt=MAX_TILT,
        heading=heading,
    )


@pytest.mark.parametrize("heading", ["goal", "nf"])
def test_cascade_kernel_is_lees_law_on_floats_and_autodiff(heading):
    """Lee's law on floats and AutoDiffXd; with ``heading: nf`` its yaw the NF's torque
    about z_B (the roll and pitch Lee's, toward z_d with the body's own heading)."""
    cascade = _cascade(heading)
    M = mixer(*rotor_layout(Quadrotor()))
    ad = cascade.ToAutoDiffXd()
    context, ad_context = cascade.CreateDefaultContext(), ad.CreateDefaultContext()
    saturated = []
    for x, f_W in _states(np.random.default_rng(7), 40):
        tau_W = np.array([0.3, -0.2, 0.1]) * 0.05  # the NF's torque: goal's leaves it unread
        force = np.concatenate([tau_W, f_W])
        cascade.generalized_force_input.FixValue(context, force)
        cascade.body_state_input.FixValue(context, x)
        wrench = np.array(cascade.wanted_wrench(context))
        truth = _lee(x, f_W, tau_W if heading == "nf" else None)
        assert np.allclose(wrench, truth, rtol=1e-12, atol=1e-12 * np.abs(truth).max())
        u = cascade.rotor_thrusts_output.Eval(context)
        flag = cascade.saturated_output.Eval(context)[0]
        assert np.all((u >= -1e-12) & (u <= MAX_THRUST + 1e-12))
        if flag == 0.0:  # nothing given up: the rotors give the wrench asked
            assert np.allclose(M @ u, wrench, atol=1e-12 * np.abs(wrench).max())
        saturated.append(flag)
        # The AutoDiffXd system (Linearize's) runs the same text in Python: same values.
        ad.generalized_force_input.FixValue(ad_context, InitializeAutoDiff(force).ravel())
        ad.body_state_input.FixValue(ad_context, InitializeAutoDiff(x).ravel())
        u_ad = ad.rotor_thrusts_output.Eval(ad_context)
        assert isinstance(u_ad[0], AutoDiffXd)
        assert np.allclose(ExtractValue(u_ad).ravel(), u, rtol=1e-13, atol=1e-13)
        assert ad.saturated_output.Eval(ad_context)[0].value() == flag
    assert 0 < sum(saturated) < len(saturated)  # both sides of the allocation's limits
    # The float system runs numba's compilation of that same text.
    assert for_scalar_type(cascade_kernel, float).py_func is cascade_kernel


@pytest.mark.parametrize("mount", ["forward", "down"])
def test_level_view_kernels_are_the_camera_on_the_level_body(mount):
    X_RC = Quadrotor(mount=mount).X_RC
    view = LevelView(X_RC=X_RC)
    ad = view.ToAutoDiffXd()
    context, ad_context = view.CreateDefaultContext(), ad.CreateDefaultContext()
    rng = np.random.default_rng(11)
    for _ in range(8):
        X_WR = RigidTransform(
            RollPitchYaw(*rng.uniform(-0.4, 0.4, 2), rng.uniform(-3, 3)), [0, 0, 1]
        )
        X_WC = X_WR @ X_RC
        X_WB = X_WC @ RigidTransform(RollPitchYaw(*rng.uniform(-0.2, 0.2, 3)), [0.02, -0.03, 0.6])
        y = camera_map(X_WC.inverse() @ X_WB, 0.1)
        y_vector = np.concatenate([y.Q[:, 0], y.Q[:, 1], y.Q[:, 2], [float(y.lam)], y.s])
        q = X_WR.rotation().ToQuaternion().wxyz() * rng.uniform(0.95, 1.05)
        x = np.concatenate([q, X_WR.translation(), rng.normal(0.0, 0.5, 6)])
        R_level = RotationMatrix.MakeZRotation(RollPitchYaw(X_WR.rotation()).yaw_angle())
        X_WCp = RigidTransform(R_level @ X_RC.rotation(), X_WC.translation())
        expected = camera_map(X_WCp.inverse() @ X_WB, 0.1)
        expected = np.concatenate(
            [
                expected.Q[:, 0],
                expected.Q[:, 1],
                expected.Q[:, 2],
                [float(expected.lam)],
                expected.s,
            ]
        )
        view.image_features_input.FixValue(context, y_vector)
        view.body_state_input.FixValue(context, x)
        got = view.level_image_features_output.Eval(context)
        assert np.allclose(got, expected, atol=1e-12)
        state = view.level_body_state_output.Eval(context)
        X_WRp = RigidTransform(Quaternion(state[0:4]), state[4:7])
        assert np.allclose((X_WRp @ X_RC).GetAsMatrix4(), X_WCp.GetAsMatrix4(), atol=1e-12)
        ad.image_features_input.FixValue(ad_context, InitializeAutoDiff(y_vector).ravel())
        ad.body_state_input.FixValue(ad_context, InitializeAutoDiff(x).ravel())
        ad_image = ExtractValue(ad.level_image_features_output.Eval(ad_context)).ravel()
        ad_state = ExtractValue(ad.level_body_state_output.Eval(ad_context)).ravel()
        assert np.allclose(ad_image, got, atol=1e-13) and np.allclose(ad_state, state, atol=1e-13)

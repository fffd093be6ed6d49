"""Pieces shared by the LeafSystems: state layout, pose packing, parameter access.

Frames (monogram notation): W world, B target sphere (the paper's F_b),
R the camera rig's body frame (origin at its centre of mass), C the camera
(pinhole, optical axis +z). The paper's H is X_CB and its G is X_BC.

Free-body state layout (MultibodyPlant, quaternion floating joint)::

    [qw, qx, qy, qz, x, y, z, wx, wy, wz, vx, vy, vz]

i.e. the pose X_WR as a quaternion and a position, then the spatial velocity
of R in W expressed in W (angular first, at R's origin).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from pydrake.math import RigidTransform

from geovs_drake._scalar import OutOfDomainError, values_or_none
from geovs_drake.domain import SafeDomain
from geovs_drake.navigation import NavigationGains

POSE_SIZE = 7
STATE_SIZE = 13


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """R(q) for q = (w, x, y, z), normalised first (as MultibodyPlant does)."""
    q = q / np.sqrt(np.sum(q * q))
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def pose_to_param(X: RigidTransform | np.ndarray) -> np.ndarray:
    """A RigidTransform (or 4x4) as the 12-vector [R column-major, p]."""
    M = X.GetAsMatrix4() if hasattr(X, "GetAsMatrix4") else np.asarray(X)
    return np.concatenate([M[:3, :3].ravel(order="F"), M[:3, 3]])


def param_to_pose(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, p) from the 12-vector of :func:`pose_to_param`, any scalar type."""
    v = np.asarray(v)
    return v[:9].reshape(3, 3, order="F"), v[9:12]


def pose_from_state(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R_WR, p_WR) from the first 7 entries of a free-body state."""
    x = np.asarray(x)
    return quaternion_to_rotation(x[0:4]), x[4:7]


def camera_pose(x_pose: np.ndarray, X_RC: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R_WC, p_WC) = X_WR X_RC."""
    R_WR, p_WR = pose_from_state(x_pose)
    R_RC, p_RC = param_to_pose(X_RC)
    return R_WR @ R_RC, p_WR + R_WR @ p_RC


def X_CB_matrix(R_WC, p_WC, R_WB, p_WB) -> np.ndarray:
    """The paper's H = X_CB = X_WC^-1 X_WB as a 4x4 array of the scalar type."""
    R_CW = R_WC.T
    X = np.zeros((4, 4), dtype=np.result_type(R_WC, R_WB))
    X[:3, :3] = R_CW @ R_WB
    X[:3, 3] = R_CW @ (p_WB - p_WC)
    X[3, 3] = 1.0
    return X


def camera_velocity(x: np.ndarray, X_RC: np.ndarray) -> np.ndarray:
    """(Omega, V): the camera's body velocity in C at Co, from a free-body state.

    With B fixed in W this is G^-1 Gdot of Eq. (16) for G = X_BC.
    """
    x = np.asarray(x)
    R_WR, _ = pose_from_state(x[0:7])
    R_RC, p_RC = param_to_pose(X_RC)
    R_WC = R_WR @ R_RC
    w_W, v_WRo_W = x[7:10], x[10:13]
    v_WCo_W = v_WRo_W + np.cross(w_W, R_WR @ p_RC)
    return np.concatenate([R_WC.T @ w_W, R_WC.T @ v_WCo_W])


def float_values(v: np.ndarray) -> np.ndarray:
    """Numeric values of a parameter vector (AutoDiffXd values, constant Expressions)."""
    out = values_or_none(v)
    if out is None:
        raise ValueError("this parameter must be numeric, not symbolic")
    return out


def domain_to_param(domain: SafeDomain) -> np.ndarray:
    return np.array(
        [domain.fov_half_angle, domain.lam_min, domain.lam_max, domain.occlusion_margin]
    )


def param_to_domain(v: np.ndarray) -> SafeDomain:
    return SafeDomain(*(float(x) for x in float_values(v)))


def gains_to_param(gains: NavigationGains) -> np.ndarray:
    return np.array([gains.k_lam, gains.k_fov, gains.k_occ, gains.circle_weight])


def param_to_gains(v: np.ndarray) -> NavigationGains:
    return NavigationGains(*(float(x) for x in float_values(v)))


def inputs_and_parameters(system) -> set:
    """Prerequisites for an output computed from the inputs and parameters only.

    Declared exactly, so Drake knows each output's feedthrough without its
    symbolic sparsity analysis (which would hand the float-only domain and gain
    parameters symbolic values), and caches on exactly these dependencies.
    """
    return {system.all_input_ports_ticket(), system.all_parameters_ticket()}


def set_output_or_nan(output, compute: Callable[[], np.ndarray]) -> None:
    """``output <- compute()``, or all NaN if its input lies outside the map's domain.

    Why: an error-controlled integrator evaluates trial stages that may step
    past the visible set V or out of the image space I, where the camera map
    and phi are undefined. Raising there would end the simulation although
    the step is about to be rejected; a NaN derivative makes Drake's integrator
    reject the step and retry a smaller one. Any *accepted* state outside D is
    caught by the safe-domain monitor of :func:`geovs_drake.simulation.simulate`,
    which stops the run with a status. Malformed input still raises.
    """
    try:
        value = compute()
    except OutOfDomainError:
        value = np.full(output.size(), np.nan)
    output.SetFromVector(value)

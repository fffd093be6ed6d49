"""Helpers the LeafSystems share: state layout, parameter packing, NaN on trial stages.

Free-body state layout (MultibodyPlant, quaternion floating joint)::

    [qw, qx, qy, qz, x, y, z, wx, wy, wz, vx, vy, vz]

i.e. the pose X_WR as a quaternion and a position, then the spatial velocity
of R in W expressed in W (angular first, at R's origin).

Each system keeps all its numbers in **one** numeric parameter vector (one
context access per evaluation, about 1.5 us each), with named accessors that
validate. A pose parameter is 12 numbers, ``[R row-major (9), p (3)]``, the
layout of :mod:`geovs_drake.geometry.rigid`.

Outside a map's domain the systems output NaN, never raise. Why: an
error-controlled integrator evaluates trial stages that may step past the
visible set V or out of the image space I, where the camera map and phi are
undefined. Raising there would end the simulation although the step is about
to be rejected; a NaN derivative makes Drake's integrator reject the step and
retry a smaller one. Any *accepted* state outside D is caught by the
safe-domain monitor of :func:`geovs_drake.simulation.simulate`, which stops the
run with a status. The generated kernels return NaN there by construction
(``error_model="numpy"``); the camera outputs NaN where nu(H) <= 0 and the NF
controller where y is not in I.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RigidTransform

from geovs_drake.geometry._ops import to_float
from geovs_drake.geometry.camera import image_violation, validate_features
from geovs_drake.geometry.domain import SafeDomain

POSE_SIZE = 7
STATE_SIZE = 13


def pose_to_param(X: RigidTransform | np.ndarray) -> list[float]:
    """A RigidTransform (or 4x4) as the 12 numbers ``[R row-major, p]``."""
    M = X.GetAsMatrix4() if hasattr(X, "GetAsMatrix4") else np.asarray(X, dtype=float)
    return M[:3, :3].ravel().tolist() + M[:3, 3].tolist()


def domain_to_param(domain: SafeDomain) -> list[float]:
    """A SafeDomain as the 4 numbers ``[theta, lam_min, lam_max, kappa]``."""
    return [domain.fov_half_angle, domain.lam_min, domain.lam_max, domain.occlusion_margin]


def param_vector(context, index, T: type) -> np.ndarray:
    """A numeric parameter as an array: a view for float (no copy), a copy otherwise
    (pydrake cannot reference object arrays)."""
    p = context.get_numeric_parameter(index)
    return p.get_value() if T is float else p.CopyToVector()


def read(context, index) -> list:
    """A numeric parameter vector's entries, as a list of the system's scalar type."""
    return context.get_numeric_parameter(index).CopyToVector().tolist()


def scalar_value(x: object) -> float | None:
    """The value of one scalar (float, AutoDiffXd, constant Expression), or None if
    it is symbolic with free variables."""
    if type(x) is float:
        return x
    v = to_float(x)
    return None if v is None else float(v)


def values_or_none(values: list) -> tuple[float, ...] | None:
    """Float values of a list of scalars (AutoDiffXd values, constant Expressions),
    or None if an entry is symbolic with free variables."""
    if type(values[0]) is float:  # a float system's values are all floats
        return tuple(values)
    out = to_float(np.array(values, dtype=object))
    return None if out is None else tuple(out.tolist())


def floats(values: list) -> tuple[float, ...]:
    """Float values of a parameter list; a symbolic parameter is an error."""
    out = values_or_none(values)
    if out is None:
        raise ValueError("this parameter must be numeric, not symbolic")
    return out


def inputs_and_parameters(system) -> set:
    """Prerequisites for an output computed from the inputs and parameters only.

    Declared exactly, so Drake knows each output's feedthrough without its
    symbolic sparsity analysis (which would hand the float-only domain and gain
    parameters symbolic values), and caches on exactly these dependencies.
    """
    return {system.all_input_ports_ticket(), system.all_parameters_ticket()}


def image_usable(y: np.ndarray) -> bool:
    """False if y's values are known and not in I (NaN from an invisible pose, or an
    integrator's trial stage outside I): the systems then output NaN, never raise."""
    values = values_or_none(y.tolist())
    return values is None or image_violation(values) is None


def twist_law_parameters(goal, radius: float, gain: float) -> list[float]:
    """``[y* (13), rho, lambda]`` of a twist-commanding baseline law, checked:
    y* in I, rho and the gain lambda [1/s] finite and > 0."""
    for name, value in (("radius", radius), ("gain", gain)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be finite and > 0, got {value}")
    return validate_features(goal).to_vector().astype(float).tolist() + [
        float(radius),
        float(gain),
    ]

"""IbvsController: point IBVS, (v, omega) = -lambda L^+ (s - s*) (Chaumette & Hutchinson 2006),
with the moving target's term -L^+ de/dt (2007, Part II)."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.baselines import (
    DEFAULT_SQUARE_SIDE,
    IBVS_DEPTHS,
    TARGET_POINT_NAMES,
    ibvs_features,
    ibvs_interaction,
    ibvs_velocity,
    pose_from_image,
    pseudo_inverse_times,
    target_points,
    twist_from_vw,
    vw_from_twist,
)
from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.target_motion import adjoint
from geovs_drake.systems._parameters import (
    floats,
    image_usable,
    inputs_and_parameters,
    read,
    twist_law_parameters,
)
from geovs_drake.systems._template import template_system

__all__ = ["IbvsController", "IbvsController_", "ibvs_target_term"]

# Layout of the one numeric parameter: y* (13), rho, lambda, square side.
_GOAL, _RHO, _GAIN, _SIDE = slice(0, 13), 13, 14, 15


def ibvs_target_term(
    y: np.ndarray,
    y_goal: np.ndarray,
    rho: object,
    P_B: np.ndarray,
    depth: str,
    twist_B: np.ndarray,
) -> np.ndarray:
    """The law's own part of the moving target's term, as (Omega, V) in C.

    Chaumette & Hutchinson 2007 (Part II, Sec. "target tracking"): with the target
    moving, ``e' = L_e v_c + de/dt``, and the law is
    ``v_c = -lambda L^+ e - L^+ de/dt``, L the law's estimate (``depth``). A target
    moving with ``twist_B`` (xi in B) moves the points as a camera moving with
    ``-Ad_{X_CB} xi`` would, so ``de/dt = -L_e Ad_{X_CB} xi`` with L_e the true
    matrix (the depths from c^-1(y)) and ``-L^+ de/dt = L^+ L_e Ad_{X_CB} xi``.
    The loop's adapter already adds ``Ad_{X_CB} xi``
    (:mod:`geovs_drake.loop.targets`), which is the whole term where L = L_e
    (``depth="true"``: L^+ L_e = I); the law adds the rest,
    ``(L^+ L_e - I) Ad_{X_CB} xi``, zero for the true depths.
    """
    if depth == "true":  # L^+ L_e = I (four points in general position: full column rank)
        return np.zeros(6)
    s, Z = ibvs_features(y, rho, P_B)
    s_goal, Z_goal = ibvs_features(y_goal, rho, P_B)
    L_law = ibvs_interaction(s, Z, s_goal, Z_goal, depth)
    L_true = ibvs_interaction(s, Z, s_goal, Z_goal, "true")
    R_CB, p_CB = pose_from_image(y, rho)
    X_CB = np.eye(4)
    X_CB[:3, :3], X_CB[:3, 3] = R_CB, p_CB
    carried = vw_from_twist(adjoint(X_CB) @ np.asarray(twist_B))
    return twist_from_vw(pseudo_inverse_times(L_law, L_true @ carried) - carried)


@template_system("IbvsController_")
def IbvsController_(T):
    class Impl(LeafSystem_[T]):
        """Point image-based visual servoing on four points of the target.

        .. pydrake_system::

            name: IbvsController
            input_ports:
            - image_features
            - target_twist
            output_ports:
            - camera_velocity

        The points are b and three corners of a square in the plane tangent
        to the sphere at b, spanned by the arrow and its normal
        (:func:`~geovs_drake.geometry.baselines.target_points`). Their
        normalised image coordinates ``s = (x_1, y_1, ..., x_4, y_4)`` and
        depths come from ``c^-1(y)`` (Eq. 23): the depths are the "true depth"
        oracle a real system would estimate. The law is Chaumette &
        Hutchinson's (*Visual servo control I*, 2006) Eq. (5),
        ``(v, omega) = -lambda L^+ (s - s*)``, with the point interaction
        matrix of their Eq. (11) and the estimate ``depth``: ``"true"`` (the
        current L with the true depths), ``"desired"`` (L at s*, Z*) or
        ``"mean"`` ((L + L*) / 2). ``camera_velocity`` is the same velocity as
        ``(Omega, V)`` in C (Eq. 16's sign; see
        :mod:`geovs_drake.geometry.baselines` for the conversion).

        An image outside I (NaN from an invisible pose, an integrator's trial
        stage) gives NaN. One numeric parameter vector ``[y* (13), rho,
        lambda, side]``: the goal image, the radius [m], the gain lambda [1/s]
        and the square's side [m].

        ``target_twist`` (optional; unconnected reads zero): the moving target's
        believed body twist xi in B, for the term ``-L^+ de/dt`` of Chaumette &
        Hutchinson 2007 (Part II) beyond the ``Ad_{X_CB} xi`` the loop adds to every
        law's twist
        (:func:`~geovs_drake.systems.ibvs_controller.ibvs_target_term`; zero with
        ``depth="true"``). Floats only, as the moving target's systems: a study's
        diagram leaves it unconnected.
        """

        #: The names of the points, in the order of :meth:`target_points_B`.
        TARGET_POINT_NAMES = TARGET_POINT_NAMES

        def _construct(
            self,
            goal: ImageFeatures | np.ndarray,
            radius: float = 0.1,
            gain: float = 1.0,
            depth: str = "true",
            side: float | None = None,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            if depth not in IBVS_DEPTHS:
                raise ValueError(
                    f"ibvs depth must be one of {', '.join(IBVS_DEPTHS)}, got {depth!r}"
                )
            side = DEFAULT_SQUARE_SIDE * radius if side is None else side
            if not (math.isfinite(side) and side > 0):
                raise ValueError(f"square side must be finite and > 0 [m], got {side}")
            params = twist_law_parameters(goal, radius, gain) + [float(side)]
            self._defaults = (np.array(params[_GOAL]), radius, gain, depth, side)
            self.depth = depth
            self._params_index = self.DeclareNumericParameter(BasicVector_[T](params))
            self.image_features_input = self.DeclareVectorInputPort(name="image_features", size=13)
            self.target_twist_input = self.DeclareVectorInputPort(name="target_twist", size=6)
            self.camera_velocity_output = self.DeclareVectorOutputPort(
                name="camera_velocity",
                size=6,
                calc=self.CalcCameraVelocity,
                prerequisites_of_calc=inputs_and_parameters(self),
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def target_points_B(self, context) -> np.ndarray:
            """The four points in B (4, 3) [m], floats, from this context's parameters."""
            p = floats(read(context, self._params_index))
            return target_points(p[_RHO], p[_SIDE])

        def CalcCameraVelocity(self, context, output) -> None:
            y = self.image_features_input.Eval(context)
            if not image_usable(y):
                output.SetFromVector([math.nan] * 6)
                return
            p = context.get_numeric_parameter(self._params_index).CopyToVector()
            P_B = target_points(p[_RHO], p[_SIDE])
            nu = ibvs_velocity(y, p[_GOAL], p[_RHO], P_B, p[_GAIN], self.depth)
            if self.target_twist_input.HasValue(context):  # a moving target's loop
                xi = self.target_twist_input.Eval(context)
                nu = nu + ibvs_target_term(y, p[_GOAL], p[_RHO], P_B, self.depth, xi)
            output.SetFromVector(nu)

    return Impl


IbvsController = IbvsController_[None]

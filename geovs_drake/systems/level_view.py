"""LevelView: the image a camera would see on the level body, from the body's attitude.

A quadrotor moves sideways by tilting, and a tilt turns its camera: the target moves in
the image as if the body had moved. The NF, reading that image, asks for more of the
same motion, so through the attitude cascade the tilt feeds itself (the down-looking
camera's loop at hover has eigenvalues at +76.6 1/s without this). The remedy of the
quadrotor IBVS literature is a virtual camera: the image de-rotated by the body's roll
and pitch, which an IMU measures (Jabbari, Oriolo & Bolandi 2014; Hamel & Mahony's
spherical features are used the same way). y's vectors (q1, q2, q3, s, all in C) turn
with the camera frame; lambda does not.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem_

from geovs_drake.systems._parameters import STATE_SIZE
from geovs_drake.systems._template import template_system

__all__ = ["LevelView", "LevelView_", "level_rotation"]


def level_rotation(R: np.ndarray) -> tuple[np.ndarray, list]:
    """The level attitude with ``R``'s heading, Rz(psi) (psi: the body x axis's heading),
    and its quaternion (w, x, y, z)."""
    n = (R[0, 0] * R[0, 0] + R[1, 0] * R[1, 0]) ** 0.5
    c, s = R[0, 0] / n, R[1, 0] / n
    zero, one = 0.0 * c, 0.0 * c + 1.0
    R_level = np.array([[c, -s, zero], [s, c, zero], [zero, zero, one]])
    # (cos psi/2, 0, 0, sin psi/2) up to scale, from whichever form is far from 0.
    w, z = (1 + c, s) if c > -0.5 else (s, 1 - c)
    m = (w * w + z * z) ** 0.5
    return R_level, [w / m, zero, zero, z / m]


def _rotation(q) -> np.ndarray:
    n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) ** 0.5
    w, x, y, z = (c / n for c in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


@template_system("LevelView_")
def LevelView_(T):
    class Impl(LeafSystem_[T]):
        """The image and the body state of a virtual camera on the level body.

        .. pydrake_system::

            name: LevelView
            input_ports:
            - image_features
            - body_state
            output_ports:
            - level_image_features
            - level_body_state

        The virtual camera C' is the camera C turned with the body's roll and pitch
        undone: R_WC' = Rz(psi) R_RC, psi the body's heading, at C's own origin.
        ``level_image_features`` is y with its vectors turned by R_C'C; NaN passes
        through. ``level_body_state`` is a free-body state whose camera, at ``X_RC`` on
        it, is C': its pose Rz(psi) and ``p_WC - Rz(psi) p_RC``, its angular velocity
        the body's, its velocity such that C' moves with C's origin (so the NF's
        damping reads C's velocity, in C'). At a level body both are the inputs.
        """

        def _construct(self, X_RC: RigidTransform | None = None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            X_RC = RigidTransform() if X_RC is None else X_RC
            self._X_RC = X_RC
            self._R_RC = X_RC.rotation().matrix()
            self._p_RC = X_RC.translation()
            self.image_features_input = self.DeclareVectorInputPort(name="image_features", size=13)
            self.body_state_input = self.DeclareVectorInputPort(name="body_state", size=STATE_SIZE)
            prerequisites = {self.all_input_ports_ticket()}
            self.level_image_features_output = self.DeclareVectorOutputPort(
                name="level_image_features",
                size=13,
                calc=self.CalcImage,
                prerequisites_of_calc=prerequisites,
            )
            self.level_body_state_output = self.DeclareVectorOutputPort(
                name="level_body_state",
                size=STATE_SIZE,
                calc=self.CalcBodyState,
                prerequisites_of_calc={self.body_state_input.ticket()},
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._X_RC, converter=converter)

        def CalcImage(self, context, output) -> None:
            x = self.body_state_input.Eval(context)
            y = self.image_features_input.Eval(context)
            R = _rotation(x[0:4])
            R_level, _ = level_rotation(R)
            # R_C'C = R_RC^T R_level^T R_WR R_RC: the camera's turn away from level.
            turn = self._R_RC.T @ (R_level.T @ R) @ self._R_RC
            out = np.empty(13, dtype=y.dtype)
            for k in (0, 3, 6, 10):
                out[k : k + 3] = turn @ y[k : k + 3]
            out[9] = y[9]
            output.SetFromVector(out)

        def CalcBodyState(self, context, output) -> None:
            x = self.body_state_input.Eval(context)
            R = _rotation(x[0:4])
            R_level, q_level = level_rotation(R)
            p_WC = x[4:7] + R @ self._p_RC
            omega, v = x[7:10], x[10:13]
            # C's origin moves at v + omega x R p_RC; the virtual body's at the same.
            v_level = v + np.cross(omega, (R - R_level) @ self._p_RC)
            out = np.concatenate([q_level, p_WC - R_level @ self._p_RC, omega, v_level])
            output.SetFromVector(out)

    return Impl


LevelView = LevelView_[None]

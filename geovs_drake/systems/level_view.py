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
from geovs_drake.systems._quadrotor_kernels import for_scalar_type, level_image, level_state
from geovs_drake.systems._template import template_system

__all__ = ["LevelView", "LevelView_"]


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
            # The kernels' parameters: [R_RC (row-major), p_RC] (_quadrotor_kernels), a
            # tuple of Python floats for AutoDiffXd's path.
            p = np.concatenate([self._R_RC.ravel(), self._p_RC])
            self._p = p if T is float else tuple(p.tolist())
            self._level_image = for_scalar_type(level_image, T)
            self._level_state = for_scalar_type(level_state, T)
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
            output.SetFromVector(self._level_image(x, y, self._p))

        def CalcBodyState(self, context, output) -> None:
            output.SetFromVector(self._level_state(self.body_state_input.Eval(context), self._p))

    return Impl


LevelView = LevelView_[None]

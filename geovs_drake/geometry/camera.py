"""The camera map c(H) = (Q, lambda, s), its inverse, visibility and the image Jacobian.

Paper: Cowan & Chang, *Toward Geometric Visual Servoing*, Sec. 2-3 and
Appendices A-B (with the corrections of docs/paper-notes.md).

Conventions (monogram notation):

* ``X_CB`` is the paper's ``H``: the pose of the target sphere's frame B in the
  camera frame C, ``p_C = X_CB p_B``. ``R = R_CB = [r1 r2 r3]``, ``d = p_CB``.
* The marked point is ``b_B = (0, 0, -rho)``; the arrow is ``a_B = e2`` (Sec. 2.3).
* ``(omega, v)`` is the right-trivialised velocity of ``X_CB`` (Eq. 11):
  ``omega = (Rdot R^T)^vee``, ``v = ddot - omega x d``. ``xi = (Qdot Q^T)^vee``
  (Eq. 13).
* The 13-vector layout of y is ``[q1, q2, q3, lambda, s]`` (Q's columns first).

Two layers:

* the formulas, in scalar style on named components (``image_of_pose``,
  ``jacobian_rows``, ``jacobian_transpose_times``, ``jacobian_inverse_times``,
  ``inverse_pose``, ``image_violation``). They take the number type's
  :class:`~geovs_drake.geometry._ops.Ops` and run on floats, float arrays of
  any batch shape, AutoDiffXd and Expression. They do not check their input:
  the Drake systems call them after one check at their boundary;
* the array API (``camera_map``, ``image_jacobian``, ...), which validates once
  and then calls the formulas.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import RigidTransform_, RotationMatrix_
from pydrake.symbolic import Expression

from geovs_drake.geometry._ops import (
    MATH,
    Ops,
    OutOfDomainError,
    any_true,
    components,
    first_bad,
    namespace,
    pack,
    to_float,
)

__all__ = [
    "UNIT_TOL",
    "ImageFeatures",
    "OutOfDomainError",
    "as_features",
    "camera_map",
    "camera_map_inverse",
    "check_image",
    "image_jacobian",
    "image_jacobian_inverse",
    "image_of_pose",
    "image_violation",
    "inverse_pose",
    "inward_normal",
    "jacobian_inverse_times",
    "jacobian_rows",
    "jacobian_transpose_times",
    "limb_margin",
    "pose_matrix",
    "ray_terms",
    "silhouette_margin",
    "validate_features",
    "visibility",
    "visibility_of_pose",
]

#: Tolerance for "Q is a rotation" and "s is a unit vector".
UNIT_TOL = 1e-9


# --------------------------------------------------------------------------
# The formulas (scalar style, no checks)
# --------------------------------------------------------------------------
def visibility_of_pose(r3: tuple, d: tuple, rho: object) -> object:
    """nu(H) = (d - rho r3) . r3 of Eq. (5), from the named components of r3 and d."""
    r3x, r3y, r3z = r3
    dx, dy, dz = d
    return (dx - rho * r3x) * r3x + (dy - rho * r3y) * r3y + (dz - rho * r3z) * r3z


def image_of_pose(r2: tuple, r3: tuple, d: tuple, rho: object, xp: Ops) -> tuple:
    """y = c(H) of Eqs. (3), (6), (7) as the 13 components ``[q1, q2, q3, lambda, s]``."""
    r2x, r2y, r2z = r2
    r3x, r3y, r3z = r3
    dx, dy, dz = d
    # Eq. (3): the silhouette's angular radius and centre.
    nd = xp.sqrt(dx * dx + dy * dy + dz * dz)
    lam = rho / nd
    sx, sy, sz = dx / nd, dy / nd, dz / nd
    # Eq. (6): q1 = b / |b| with b = d - rho r3 ...
    bx, by, bz = dx - rho * r3x, dy - rho * r3y, dz - rho * r3z
    nb = xp.sqrt(bx * bx + by * by + bz * bz)
    q1x, q1y, q1z = bx / nb, by / nb, bz / nb
    # ... and q2 is r2 projected on T_q1 S^2, normalised.
    c = q1x * r2x + q1y * r2y + q1z * r2z
    gx, gy, gz = r2x - c * q1x, r2y - c * q1y, r2z - c * q1z
    ng = xp.sqrt(gx * gx + gy * gy + gz * gz)
    q2x, q2y, q2z = gx / ng, gy / ng, gz / ng
    # Eq. (7): q3 = q1 x q2.
    q3x = q1y * q2z - q1z * q2y
    q3y = q1z * q2x - q1x * q2z
    q3z = q1x * q2y - q1y * q2x
    return (q1x, q1y, q1z, q2x, q2y, q2z, q3x, q3y, q3z, lam, sx, sy, sz)


def limb_terms(y: tuple) -> tuple:
    """``(cos phi, sin^2 phi)`` for the angle phi from s to q1 (Eqs. 14, 21).

    Per the errata's numerics, sin^2 phi is not formed as 1 - (s.q1)^2, which
    loses every digit at small lambda. It is |s x q1|^2: exact to rounding,
    and, unlike |s x q1|, differentiable at phi = 0 (the goal image has
    q1 = s), so AutoDiffXd gives finite derivatives there.
    """
    return ray_terms((y[0], y[1], y[2]), (y[10], y[11], y[12]))


def ray_terms(x: tuple, s: tuple) -> tuple:
    """``(x.s, |s x x|^2)`` for unit vectors x and s: :func:`limb_terms` for any ray x."""
    q1x, q1y, q1z = x
    sx, sy, sz = s
    wx, wy, wz = sy * q1z - sz * q1y, sz * q1x - sx * q1z, sx * q1y - sy * q1x
    return sx * q1x + sy * q1y + sz * q1z, wx * wx + wy * wy + wz * wz


def inward_normal(x: tuple, lam: object, s: tuple, xp: Ops) -> tuple:
    """``(d - p) / rho``: the unit normal, pointing to the centre, where the ray x meets the sphere.

    p is the nearer of the two points where the unit ray x (inside the
    silhouette: ``|s x x| < lambda``) meets the sphere of centre
    ``d = (rho / lambda) s``; by Eq. (21) ``p = |p| x`` with
    ``|p| = (rho / lambda)(x.s - sqrt(lambda^2 - |s x x|^2))``, so
    ``(d - p) / rho = (s - f x) / lambda``, ``f = x.s - sqrt(lambda^2 - |s x x|^2)``.
    For x = q1 this is Eq. (23)'s r3. It does not depend on rho: the image fixes
    the shape of the scene, not its scale.
    """
    cos_phi, sin2 = ray_terms(x, s)
    f = cos_phi - xp.sqrt(lam * lam - sin2)
    return (s[0] - f * x[0]) / lam, (s[1] - f * x[1]) / lam, (s[2] - f * x[2]) / lam


def limb_margin(y: tuple, xp: Ops) -> object:
    """``q1.s - sqrt(1 - lambda^2)`` of Eq. (9) for q1.s > 0, without cancellation.

    At small lambda both terms are near 1 and their difference, about
    lambda^2 / 2, loses its digits. For unit q1, s with q1.s > 0 it equals
    ``(lambda^2 - |s x q1|^2) / (q1.s + sqrt(1 - lambda^2))``, which keeps them.
    """
    lam = y[9]
    cos_phi, sin2 = limb_terms(y)
    return (lam * lam - sin2) / (cos_phi + xp.sqrt(1 - lam * lam))


def _beta_delta(y: tuple, rho: object, xp: Ops) -> tuple:
    """beta = |b| of Eq. (21) (the errata: Eq. 41 is misprinted) and
    delta = (s.q2) / sqrt(lambda^2 - sin^2 phi) of Eq. (14)."""
    lam = y[9]
    cos_phi, sin2 = limb_terms(y)
    root = xp.sqrt(lam * lam - sin2)
    beta = (rho / lam) * (cos_phi - root)
    return beta, (y[10] * y[3] + y[11] * y[4] + y[12] * y[5]) / root


def jacobian_rows(y: tuple, rho: object, xp: Ops) -> tuple:
    """C(y) of Eq. (14) as 7 rows of 6 entries.

    ``(xi, lambda_dot, s_dot) = C(y) (omega, v)`` for the right-trivialised
    velocity of X_CB (Eq. 11); ``beta = |b|`` of Eq. (21) (the errata: Eq. 41 is
    misprinted) and ``delta = (s.q2) / sqrt(lambda^2 - sin^2 phi)``.
    """
    q1x, q1y, q1z, q2x, q2y, q2z, q3x, q3y, q3z, lam, sx, sy, sz = y
    beta, delta = _beta_delta(y, rho, xp)
    # Top right block (delta q1 q3^T - q2 q3^T + q3 q2^T) / beta; m = delta q1 - q2.
    mx, my, mz = (delta * q1x - q2x) / beta, (delta * q1y - q2y) / beta, (delta * q1z - q2z) / beta
    ux, uy, uz = q3x / beta, q3y / beta, q3z / beta
    a = -lam * lam / rho
    k = lam / rho
    return (
        (1.0, 0.0, 0.0, mx * q3x + ux * q2x, mx * q3y + ux * q2y, mx * q3z + ux * q2z),
        (0.0, 1.0, 0.0, my * q3x + uy * q2x, my * q3y + uy * q2y, my * q3z + uy * q2z),
        (0.0, 0.0, 1.0, mz * q3x + uz * q2x, mz * q3y + uz * q2y, mz * q3z + uz * q2z),
        (0.0, 0.0, 0.0, a * sx, a * sy, a * sz),
        # s_dot = -hat(s) omega + (lambda / rho) (I - s s^T) v.
        (0.0, sz, -sy, k * (1 - sx * sx), -k * sx * sy, -k * sx * sz),
        (-sz, 0.0, sx, -k * sy * sx, k * (1 - sy * sy), -k * sy * sz),
        (sy, -sx, 0.0, -k * sz * sx, -k * sz * sy, k * (1 - sz * sz)),
    )


def jacobian_transpose_times(rows: tuple, x: tuple) -> tuple:
    """``C^T x`` from :func:`jacobian_rows` and a 7-tuple ``x`` (unrolled: no numpy call)."""
    r0, r1, r2, r3, r4, r5, r6 = rows
    x0, x1, x2, x3, x4, x5, x6 = x
    return tuple(
        r0[j] * x0 + r1[j] * x1 + r2[j] * x2 + r3[j] * x3 + r4[j] * x4 + r5[j] * x5 + r6[j] * x6
        for j in range(6)
    )


def jacobian_inverse_times(y: tuple, rho: object, x: tuple, xp: Ops) -> tuple:
    """``Tc^-1 x`` of Eq. (15) in closed form: the ``(omega, v)`` that C maps to x.

    On the range of C (7-vectors whose s-part is orthogonal to s) this is the
    exact inverse of C, as Eq. (15) says; the s-part of x is first projected on
    T_s S^2, which makes it the least-squares solution ``(C^T C)^-1 C^T x`` of
    Eq. (15) everywhere (the range is the orthogonal complement of (0, 0, s)).

    Derivation (no 6x6 solve): with ``d = (rho/lambda) s``,
    ``ddot = -(rho/lambda^2) lambda_dot s + (rho/lambda) s_dot`` (Eq. 3), and
    ``ddot = omega x d + v`` (Eq. 11), ``xi = omega + T v`` (Eq. 14's top row,
    ``T v = (a m + b q3) / beta`` with ``m = delta q1 - q2``, ``a = q3.v``,
    ``b = q2.v``). Eliminating omega, ``v = e + (T v) x d`` with
    ``e = ddot - xi x d``; dotting with q3 and then q2 gives a triangular 2x2
    system for (a, b).
    """
    q1x, q1y, q1z, q2x, q2y, q2z, q3x, q3y, q3z, lam, sx, sy, sz = y
    xi_x, xi_y, xi_z, lam_dot, tx, ty, tz = x
    beta, delta = _beta_delta(y, rho, xp)
    st = sx * tx + sy * ty + sz * tz
    tx, ty, tz = tx - st * sx, ty - st * sy, tz - st * sz
    r = rho / lam
    dx, dy, dz = r * sx, r * sy, r * sz
    c = -r * lam_dot / lam
    ddx, ddy, ddz = c * sx + r * tx, c * sy + r * ty, c * sz + r * tz
    ex = ddx - (xi_y * dz - xi_z * dy)
    ey = ddy - (xi_z * dx - xi_x * dz)
    ez = ddz - (xi_x * dy - xi_y * dx)
    mx, my, mz = delta * q1x - q2x, delta * q1y - q2y, delta * q1z - q2z
    # m x d and q3 x d.
    mdx, mdy, mdz = my * dz - mz * dy, mz * dx - mx * dz, mx * dy - my * dx
    qdx, qdy, qdz = q3y * dz - q3z * dy, q3z * dx - q3x * dz, q3x * dy - q3y * dx
    a = (q3x * ex + q3y * ey + q3z * ez) / (1 - (q3x * mdx + q3y * mdy + q3z * mdz) / beta)
    b = (q2x * ex + q2y * ey + q2z * ez + a * (q2x * mdx + q2y * mdy + q2z * mdz) / beta) / (
        1 - (q2x * qdx + q2y * qdy + q2z * qdz) / beta
    )
    vx = ex + (a * mdx + b * qdx) / beta
    vy = ey + (a * mdy + b * qdy) / beta
    vz = ez + (a * mdz + b * qdz) / beta
    wx = xi_x - (a * mx + b * q3x) / beta
    wy = xi_y - (a * my + b * q3y) / beta
    wz = xi_z - (a * mz + b * q3z) / beta
    return (wx, wy, wz, vx, vy, vz)


def inverse_pose(y: tuple, rho: object, xp: Ops) -> tuple:
    """c^-1(y) of Eq. (23) as ``(r1, r2, r3, d)``, each a 3-tuple.

    Eq. (23) writes ``r2 ~ q2 - (r3.q2 / r3.q1) q1``. Multiplied by
    ``r3.q1 > 0`` this is ``(r3.q1) q2 - (r3.q2) q1 = q3 x r3``: the same
    direction without dividing by ``r3.q1 = nu / |b|``, which near the
    visibility boundary cost 7 digits.
    """
    q1x, q1y, q1z, q2x, q2y, q2z, q3x, q3y, q3z, lam, sx, sy, sz = y
    r = rho / lam
    r3x, r3y, r3z = inward_normal((q1x, q1y, q1z), lam, (sx, sy, sz), xp)
    gx, gy, gz = q3y * r3z - q3z * r3y, q3z * r3x - q3x * r3z, q3x * r3y - q3y * r3x
    ng = xp.sqrt(gx * gx + gy * gy + gz * gz)
    r2x, r2y, r2z = gx / ng, gy / ng, gz / ng
    r1 = (r2y * r3z - r2z * r3y, r2z * r3x - r2x * r3z, r2x * r3y - r2y * r3x)
    return r1, (r2x, r2y, r2z), (r3x, r3y, r3z), (r * sx, r * sy, r * sz)


class Violation(NamedTuple):
    """A broken condition of y in I: message template, values, mask and error class."""

    template: str
    values: object
    bad: object
    error: type

    def raise_error(self) -> None:
        value, where = first_bad(self.values, self.bad)
        raise self.error(self.template.format(value=value) + where)


_NAMES = ("q1",) * 3 + ("q2",) * 3 + ("q3",) * 3 + ("lambda",) + ("s",) * 3


def _max_abs(*xs: object) -> object:
    if type(xs[0]) is not np.ndarray:
        return max(abs(xs[0]), abs(xs[1]), abs(xs[2]), abs(xs[3]), abs(xs[4]), abs(xs[5]))
    return np.max(np.abs(np.stack(np.broadcast_arrays(*xs))), axis=0)


def image_violation(y: tuple) -> Violation | None:
    """The first condition of y in I (Eq. 9) that float components break, or None.

    Components are floats or float arrays of one batch shape; for a single y
    the check costs a few microseconds.
    """
    q1x, q1y, q1z, q2x, q2y, q2z, q3x, q3y, q3z, lam, sx, sy, sz = y
    batch = type(lam) is np.ndarray
    if batch:
        finite = np.isfinite(np.stack(y))
        all_finite = finite.all()
    else:
        all_finite = all(map(math.isfinite, y))
    if not all_finite:
        if not batch:
            finite = np.isfinite(np.array(y))
        k = int(np.argwhere(~finite)[0][0])
        return Violation(
            f"{_NAMES[k]} has a non-finite entry: y[{k}] = {{value}}",
            y[k],
            ~finite[k],
            OutOfDomainError,
        )
    bad = (lam <= 0) | (lam >= 1)
    if any_true(bad):
        return Violation("lambda outside (0, 1): lambda = {value:.6g}", lam, bad, OutOfDomainError)
    # Q^T Q = I and det Q = +1.
    err = _max_abs(
        q1x * q1x + q1y * q1y + q1z * q1z - 1,
        q2x * q2x + q2y * q2y + q2z * q2z - 1,
        q3x * q3x + q3y * q3y + q3z * q3z - 1,
        q1x * q2x + q1y * q2y + q1z * q2z,
        q1x * q3x + q1y * q3y + q1z * q3z,
        q2x * q3x + q2y * q3y + q2z * q3z,
    )
    det = (
        q3x * (q1y * q2z - q1z * q2y)
        + q3y * (q1z * q2x - q1x * q2z)
        + q3z * (q1x * q2y - q1y * q2x)
    )
    bad = (err > UNIT_TOL) | (det <= 0)
    if any_true(bad):
        return Violation(
            f"Q is not a rotation: max|Q^T Q - I| = {{value:.3g}} (tol {UNIT_TOL:g}) "
            "or det(Q) <= 0",
            err,
            bad,
            ValueError,
        )
    s_err = abs(namespace(lam).sqrt(sx * sx + sy * sy + sz * sz) - 1)
    bad = s_err > UNIT_TOL
    if any_true(bad):
        return Violation(
            "s is not a unit vector: | |s| - 1 | = {value:.3g}", s_err, bad, ValueError
        )
    # Eq. (9): the marked point strictly inside the silhouette disc.
    margin = silhouette_margin(y)
    bad = margin <= 0
    if any_true(bad):
        return Violation(
            "y not in I: q1.s - sqrt(1 - lambda^2) = {value:.6g} <= 0",
            margin,
            bad,
            OutOfDomainError,
        )
    return None


def silhouette_margin(y: tuple) -> object:
    """:func:`limb_margin` for float components, including q1.s <= 0 (beyond the limb)."""
    lam = y[9]
    c = y[0] * y[10] + y[1] * y[11] + y[2] * y[12]
    if type(lam) is not np.ndarray:
        return limb_margin(y, MATH) if c > 0 else c - math.sqrt(1 - lam * lam)
    with np.errstate(divide="ignore", invalid="ignore"):
        stable = limb_margin(y, namespace(lam))
    return np.where(c > 0, stable, c - np.sqrt(1 - lam**2))


def check_image(y: tuple) -> None:
    """Raise a ValueError naming the broken condition if float components y are not in I."""
    broken = image_violation(y)
    if broken is not None:
        broken.raise_error()


# --------------------------------------------------------------------------
# The array API: ImageFeatures, validation once, then the formulas
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class ImageFeatures:
    """The image y = (Q, lambda, s) of Eq. (8).

    ``Q`` has shape (..., 3, 3) with columns ``q1, q2, q3``; ``lam`` has shape
    (...); ``s`` has shape (..., 3).
    """

    Q: np.ndarray
    lam: np.ndarray
    s: np.ndarray

    @property
    def q1(self) -> np.ndarray:
        """q1, the unit vector towards the marked point (Eq. 6): Q's first column."""
        return self.Q[..., :, 0]

    @property
    def q2(self) -> np.ndarray:
        """q2, the arrow's direction orthogonal to q1 (Eq. 7): Q's second column."""
        return self.Q[..., :, 1]

    @property
    def q3(self) -> np.ndarray:
        """q3 = q1 x q2: Q's third column."""
        return self.Q[..., :, 2]

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The shape of the batch, ``()`` for one image."""
        return np.shape(self.lam)

    def to_vector(self) -> np.ndarray:
        """The 13-vector ``[q1, q2, q3, lambda, s]`` (shape (..., 13))."""
        lam = np.asarray(self.lam)[..., None]
        return np.concatenate([self.q1, self.q2, self.q3, lam, self.s], axis=-1)

    def __array__(self, dtype: object = None, copy: bool | None = None) -> np.ndarray:
        """numpy's view of y: :meth:`to_vector`, the layout of the systems' 13-vector
        ports, so that ``np.asarray(y)``, ``np.round(y, 3)`` and a port's ``FixValue``
        take an ImageFeatures as it is."""
        v = self.to_vector()
        return v if dtype is None else v.astype(dtype, copy=False)

    def components(self) -> tuple:
        """The 13 named components the formulas take."""
        return components(self.to_vector(), 13, "y")

    @staticmethod
    def from_vector(v: np.ndarray) -> ImageFeatures:
        """Inverse of :meth:`to_vector`."""
        v = np.asarray(v)
        if v.shape[-1:] != (13,):
            raise ValueError(f"image feature vector must have shape (..., 13), got {v.shape}")
        if v.dtype != object:
            v = v.astype(float, copy=False)
        Q = np.stack([v[..., 0:3], v[..., 3:6], v[..., 6:9]], axis=-1)
        return ImageFeatures(Q=Q, lam=v[..., 9], s=v[..., 10:13])

    @staticmethod
    def from_components(y: tuple) -> ImageFeatures:
        """From the 13 named components of :meth:`components`."""
        return ImageFeatures.from_vector(pack(y))

    def __getitem__(self, index: object) -> ImageFeatures:
        """Index the batch dimensions."""
        return ImageFeatures(self.Q[index], np.asarray(self.lam)[index], self.s[index])


def as_features(y: ImageFeatures | np.ndarray) -> ImageFeatures:
    """Accept either :class:`ImageFeatures` or a (..., 13) vector."""
    if isinstance(y, ImageFeatures):
        Q, lam, s = np.asarray(y.Q), np.asarray(y.lam), np.asarray(y.s)
        if Q.shape[-2:] != (3, 3) or s.shape[-1:] != (3,) or Q.shape[:-2] != lam.shape:
            raise ValueError(
                f"ImageFeatures shapes are inconsistent: Q {Q.shape}, lam {lam.shape}, s {s.shape}"
            )
        return y
    return ImageFeatures.from_vector(y)


def validated_components(y: ImageFeatures | np.ndarray) -> tuple:
    """y's 13 components after checking that y lies in I (Eq. 9); any scalar type.

    AutoDiffXd and constant Expressions are checked on their values; symbolic
    entries with free variables cannot be, and pass unchecked.
    """
    v = as_features(y).to_vector()
    values = to_float(v)
    if values is not None:
        check_image(components(values, 13, "y"))
    return components(v, 13, "y")


def validate_features(y: ImageFeatures | np.ndarray) -> ImageFeatures:
    """Check that y lies in the image space I of Eq. (9); return it as ImageFeatures.

    Raises ValueError naming the broken condition and its value.
    """
    validated_components(y)
    return as_features(y)


def pose_matrix(X_CB: object) -> np.ndarray:
    """``X_CB`` as a (..., 4, 4) array, from a RigidTransform of any scalar type."""
    if hasattr(X_CB, "GetAsMatrix4"):
        return X_CB.GetAsMatrix4()
    X = np.asarray(X_CB)
    if X.shape[-2:] != (4, 4):
        raise ValueError(f"X_CB must be a RigidTransform or a (..., 4, 4) array, got {X.shape}")
    return X if X.dtype == object else X.astype(float, copy=False)


def _check_radius(radius: object) -> None:
    r = to_float(radius)
    if r is None:
        return
    if r.shape != ():
        raise ValueError(f"radius must be a scalar, got shape {r.shape}")
    if not np.isfinite(r) or r <= 0:
        raise ValueError(f"radius must be finite and > 0: radius = {float(r)}")


def _pose_components(X_CB: object) -> tuple[tuple, tuple, tuple]:
    """(r2, r3, d) of a checked pose, as the formulas' named components."""
    X = pose_matrix(X_CB)
    v = to_float(X)
    if v is not None:
        if not np.all(np.isfinite(v)):
            idx = tuple(int(i) for i in np.argwhere(~np.isfinite(v))[0])
            raise OutOfDomainError(f"X_CB has a non-finite entry: X_CB[{idx}] = {v[idx]}")
        bottom = np.max(np.abs(v[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])), axis=-1)
        if np.any(bottom > 1e-12):
            value, where = first_bad(bottom, bottom > 1e-12)
            raise ValueError(
                f"X_CB is not homogeneous: last row differs from [0, 0, 0, 1] by {value:.3g}{where}"
            )
        R = v[..., :3, :3]
        err = np.max(np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)), axis=(-2, -1))
        bad = (err > UNIT_TOL) | (np.linalg.det(R) <= 0)
        if np.any(bad):
            value, where = first_bad(err, bad)
            raise ValueError(
                f"X_CB rotation is not a rotation: max|R^T R - I| = {value:.3g} "
                f"(tol {UNIT_TOL:g}) or det(R) <= 0{where}"
            )
    cols = components(np.moveaxis(X[..., :3, :], -1, -2).reshape(X.shape[:-2] + (12,)), 12, "X")
    return cols[3:6], cols[6:9], cols[9:12]


def visibility(X_CB: object, radius: object) -> np.ndarray:
    """nu(H) of Eq. (5): positive iff the marked point b faces the camera."""
    _check_radius(radius)
    _, r3, d = _pose_components(X_CB)
    return np.asarray(visibility_of_pose(r3, d, radius))


def camera_map(X_CB: object, radius: object) -> ImageFeatures:
    """The camera map c(H) of Eqs. (3), (6), (7), (8).

    Raises:
        ValueError: if the pose is not visible (nu(H) <= 0), the radius is not
            positive, or the input is malformed or not finite.
    """
    _check_radius(radius)
    r2, r3, d = _pose_components(X_CB)
    nu = to_float(visibility_of_pose(r3, d, radius))
    if nu is not None and np.any(nu <= 0):
        value, where = first_bad(nu, nu <= 0)
        raise OutOfDomainError(f"pose not visible: nu(H) = {value:.6g} <= 0{where}")
    return ImageFeatures.from_components(image_of_pose(r2, r3, d, radius, namespace(d[0])))


def camera_map_inverse(y: ImageFeatures | np.ndarray, radius: object) -> object:
    """The inverse camera map c^-1(y) of Eq. (23).

    Returns a ``RigidTransform`` of y's scalar type for a single y, or a
    (..., 4, 4) float array for a batch.
    """
    _check_radius(radius)
    comps = validated_components(y)
    r1, r2, r3, d = inverse_pose(comps, radius, namespace(comps[9]))
    rows = [pack((r1[i], r2[i], r3[i], d[i])) for i in range(3)]
    if rows[0].ndim == 1:
        T = _scalar_type(rows[0])
        R = np.stack([r[:3] for r in rows])
        return RigidTransform_[T](RotationMatrix_[T](R), np.array([r[3] for r in rows]))
    X = np.zeros(rows[0].shape[:-1] + (4, 4), dtype=rows[0].dtype)
    for i in range(3):
        X[..., i, :] = rows[i]
    X[..., 3, 3] = 1.0
    return X


def _scalar_type(a: np.ndarray) -> type:
    if a.dtype != object:
        return float
    return AutoDiffXd if any(isinstance(e, AutoDiffXd) for e in a.flat) else Expression


def _matrix(rows: tuple) -> np.ndarray:
    """Rows of components (scalars or batch arrays) as a (..., m, n) array."""
    return np.stack([pack(row) for row in rows], axis=-2)


def image_jacobian(y: ImageFeatures | np.ndarray, radius: object) -> np.ndarray:
    """C(y) of Eq. (14), shape (..., 7, 6).

    Maps the right-trivialised velocity ``(omega, v)`` of ``X_CB`` (Eq. 11) to
    ``(xi, lambda_dot, s_dot)`` (Eqs. 12-13). ``beta = |b|`` of Eq. (21).
    """
    _check_radius(radius)
    comps = validated_components(y)
    return _matrix(jacobian_rows(comps, radius, namespace(comps[9])))


def image_jacobian_inverse(y: ImageFeatures | np.ndarray, radius: object) -> np.ndarray:
    """Tc^-1 of Eq. (15), shape (..., 6, 7), in closed form (:func:`jacobian_inverse_times`).

    On the range of C (the 7-vectors whose s-part is orthogonal to s) this is the
    exact inverse of C: the paper's point is that T_y I is a 6-dimensional
    subspace of R^7, not that a least-squares fit is being made. Elsewhere it
    is ``(C^T C)^-1 C^T``, the least-squares solution.
    """
    _check_radius(radius)
    comps = validated_components(y)
    xp = namespace(comps[9])
    units = [tuple(1.0 if i == k else 0.0 for i in range(7)) for k in range(7)]
    cols = [jacobian_inverse_times(comps, radius, e, xp) for e in units]
    return _matrix(tuple(tuple(col[i] for col in cols) for i in range(6)))

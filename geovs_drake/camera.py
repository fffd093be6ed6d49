"""The camera map c(H) = (Q, lambda, s), its inverse and the image Jacobian.

Paper: Cowan & Chang, *Toward Geometric Visual Servoing*, Sec. 2-3 and
Appendices A-B, with the errata in ``shared/paper/ERRATA.md``.

Conventions (monogram notation):

* ``X_CB`` is the paper's ``H``: the pose of the target sphere's frame B in the
  camera frame C, ``p_C = X_CB p_B``. ``R = R_CB = [r1 r2 r3]``, ``d = p_CB``.
* The marked point is ``b_B = (0, 0, -rho)``; the arrow is ``a_B = e2`` (Sec. 2.3).
* ``(omega, v)`` is the right-trivialised velocity of ``X_CB`` (Eq. 11):
  ``omega = (Rdot R^T)^vee``, ``v = ddot - omega x d``. ``xi = (Qdot Q^T)^vee``
  (Eq. 13).
* The 13-vector layout of y is ``[q1, q2, q3, lambda, s]`` (Q's columns first).

Every function is scalar-generic (float, AutoDiffXd, Expression object arrays),
and float inputs may carry leading batch dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pydrake.math as pm
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import RigidTransform_, RotationMatrix_
from pydrake.symbolic import Expression

from geovs_drake._scalar import (
    OutOfDomainError,
    as_array,
    check_finite,
    col,
    cross,
    dot,
    index_note,
    mat,
    norm,
    outer,
    values_or_none,
    worst,
)
from geovs_drake.so3 import hat

__all__ = [
    "ImageFeatures",
    "OutOfDomainError",
    "camera_map",
    "camera_map_inverse",
    "image_jacobian",
    "image_jacobian_inverse",
    "pose_matrix",
    "limb_margin",
    "silhouette_margin",
    "validate_features",
    "visibility",
]

#: Tolerance for "Q is a rotation" and "s is a unit vector".
UNIT_TOL = 1e-9


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
        return self.Q[..., :, 0]

    @property
    def q2(self) -> np.ndarray:
        return self.Q[..., :, 1]

    @property
    def q3(self) -> np.ndarray:
        return self.Q[..., :, 2]

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return np.shape(self.lam)

    def to_vector(self) -> np.ndarray:
        """The 13-vector ``[q1, q2, q3, lambda, s]`` (shape (..., 13))."""
        lam = col(self.lam)
        return np.concatenate([self.q1, self.q2, self.q3, lam, self.s], axis=-1)

    @staticmethod
    def from_vector(v: np.ndarray) -> ImageFeatures:
        """Inverse of :meth:`to_vector`."""
        v = as_array(v)
        if v.shape[-1:] != (13,):
            raise ValueError(f"image feature vector must have shape (..., 13), got {v.shape}")
        Q = np.stack([v[..., 0:3], v[..., 3:6], v[..., 6:9]], axis=-1)
        return ImageFeatures(Q=Q, lam=v[..., 9], s=v[..., 10:13])

    def __getitem__(self, index: object) -> ImageFeatures:
        """Index the batch dimensions."""
        return ImageFeatures(self.Q[index], as_array(self.lam)[index], self.s[index])


def as_features(y: ImageFeatures | np.ndarray) -> ImageFeatures:
    """Accept either :class:`ImageFeatures` or a (..., 13) vector."""
    if isinstance(y, ImageFeatures):
        return ImageFeatures(as_array(y.Q), as_array(y.lam), as_array(y.s))
    return ImageFeatures.from_vector(y)


def pose_matrix(X_CB: object) -> np.ndarray:
    """``X_CB`` as a (..., 4, 4) array, from a RigidTransform of any scalar type."""
    if hasattr(X_CB, "GetAsMatrix4"):
        return X_CB.GetAsMatrix4()
    X = as_array(X_CB)
    if X.shape[-2:] != (4, 4):
        raise ValueError(f"X_CB must be a RigidTransform or a (..., 4, 4) array, got {X.shape}")
    return X


def _check_radius(radius: object) -> None:
    r = values_or_none(radius)
    if r is None:
        return
    if r.shape != ():
        raise ValueError(f"radius must be a scalar, got shape {r.shape}")
    if not np.isfinite(r) or r <= 0:
        raise ValueError(f"radius must be finite and > 0: radius = {float(r)}")


def _check_pose(X: np.ndarray) -> None:
    check_finite("X_CB", X)
    v = values_or_none(X)
    if v is None:
        return
    bottom_err = np.max(np.abs(v[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])), axis=-1)
    if np.any(bottom_err > 1e-12):
        val, idx = worst(bottom_err, bottom_err > 1e-12)
        raise ValueError(
            f"X_CB is not homogeneous: last row differs from [0, 0, 0, 1]{index_note(idx)}"
        )
    R = v[..., :3, :3]
    err = np.max(np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)), axis=(-2, -1))
    bad = (err > UNIT_TOL) | (np.linalg.det(R) <= 0)
    if np.any(bad):
        val, idx = worst(err, bad)
        raise ValueError(
            f"X_CB rotation is not a rotation: max|R^T R - I| = {val:.3g} > {UNIT_TOL:g} "
            f"or det(R) <= 0{index_note(idx)}"
        )


def _nu(X: np.ndarray, radius: object) -> np.ndarray:
    # Eq. (5): nu(H) = (d - rho r3) . r3.
    r3 = X[..., :3, 2]
    d = X[..., :3, 3]
    return dot(d - radius * r3, r3)


def visibility(X_CB: object, radius: object) -> np.ndarray:
    """nu(H) of Eq. (5): positive iff the marked point b faces the camera."""
    _check_radius(radius)
    X = pose_matrix(X_CB)
    _check_pose(X)
    return _nu(X, radius)


def camera_map(X_CB: object, radius: object) -> ImageFeatures:
    """The camera map c(H) of Eqs. (3), (6), (7), (8).

    Raises:
        ValueError: if the pose is not visible (nu(H) <= 0), the radius is not
            positive, or the input is malformed or not finite.
    """
    _check_radius(radius)
    X = pose_matrix(X_CB)
    _check_pose(X)
    nu_v = values_or_none(_nu(X, radius))
    if nu_v is not None and np.any(nu_v <= 0):
        val, idx = worst(nu_v, nu_v <= 0)
        raise OutOfDomainError(f"pose not visible: nu(H) = {val:.6g} <= 0{index_note(idx)}")
    r2 = X[..., :3, 1]
    r3 = X[..., :3, 2]
    d = X[..., :3, 3]
    # Eq. (3): the silhouette's angular radius and centre.
    nd = norm(d)
    lam = np.asarray(radius / nd)
    s = d / col(nd)
    # Eq. (6): q1 = b / |b| with b = d - rho r3; q2 is r2 projected on T_q1 S^2.
    b = d - radius * r3
    q1 = b / col(norm(b))
    g = r2 - col(dot(q1, r2)) * q1
    q2 = g / col(norm(g))
    # Eq. (7).
    q3 = cross(q1, q2)
    Q = np.stack([q1, q2, q3], axis=-1)
    return ImageFeatures(Q=Q, lam=lam, s=s)


def limb_margin(q1: np.ndarray, lam: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``q1.s - sqrt(1 - lambda^2)`` of Eq. (9) for q1.s > 0, without cancellation.

    At small lambda both terms are near 1 and their difference, about
    lambda^2 / 2, loses its digits. For unit q1, s with q1.s > 0 it equals
    ``(lambda^2 - |s x q1|^2) / (q1.s + sqrt(1 - lambda^2))``, which keeps them.
    Scalar-generic (the safe domain's occlusion margin uses it too).
    """
    w = cross(s, q1)
    return (lam * lam - dot(w, w)) / (dot(q1, s) + np.sqrt(1 - lam * lam))


def silhouette_margin(q1: np.ndarray, lam: np.ndarray, s: np.ndarray) -> np.ndarray:
    """:func:`limb_margin` for any float q1, including q1.s <= 0 (far side of the limb)."""
    c = np.sum(q1 * s, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        stable = limb_margin(q1, lam, s)
    return np.where(c > 0, stable, c - np.sqrt(1 - lam**2))


def validate_features(y: ImageFeatures | np.ndarray) -> ImageFeatures:
    """Check that y lies in the image space I of Eq. (9); return it as ImageFeatures.

    Raises ValueError naming the broken condition and its value.
    """
    if isinstance(y, ImageFeatures):
        Q, lam, s = as_array(y.Q), as_array(y.lam), as_array(y.s)
        if Q.shape[-2:] != (3, 3) or s.shape[-1:] != (3,) or Q.shape[:-2] != lam.shape:
            raise ValueError(
                f"ImageFeatures shapes are inconsistent: Q {Q.shape}, lam {lam.shape}, s {s.shape}"
            )
        y = ImageFeatures(Q, lam, s)
    else:
        y = as_features(y)
    for name, x in (("Q", y.Q), ("lambda", y.lam), ("s", y.s)):
        check_finite(name, x)
    Qv, lamv, sv = values_or_none(y.Q), values_or_none(y.lam), values_or_none(y.s)
    if lamv is not None:
        bad = (lamv <= 0) | (lamv >= 1)
        if np.any(bad):
            val, idx = worst(lamv, bad)
            raise OutOfDomainError(f"lambda outside (0, 1): lambda = {val:.6g}{index_note(idx)}")
    if Qv is not None:
        err = np.max(np.abs(np.swapaxes(Qv, -1, -2) @ Qv - np.eye(3)), axis=(-2, -1))
        det = np.linalg.det(Qv)
        bad = (err > UNIT_TOL) | (det <= 0)
        if np.any(bad):
            val, idx = worst(err, bad)
            raise ValueError(
                f"Q is not a rotation: max|Q^T Q - I| = {val:.3g} (tol {UNIT_TOL:g}), "
                f"det(Q) = {float(det[idx]):.6g}{index_note(idx)}"
            )
    if sv is not None:
        err = np.abs(np.linalg.norm(sv, axis=-1) - 1.0)
        if np.any(err > UNIT_TOL):
            val, idx = worst(err, err > UNIT_TOL)
            raise ValueError(f"s is not a unit vector: | |s| - 1 | = {val:.3g}{index_note(idx)}")
    if Qv is not None and lamv is not None and sv is not None:
        # Eq. (9): the marked point lies strictly inside the silhouette disc.
        margin = silhouette_margin(Qv[..., :, 0], lamv, sv)
        bad = margin <= 0
        if np.any(bad):
            val, idx = worst(margin, bad)
            raise OutOfDomainError(
                f"y not in I: q1.s - sqrt(1 - lambda^2) = {val:.6g} <= 0{index_note(idx)}"
            )
    return y


def _phi_terms(y: ImageFeatures) -> tuple[np.ndarray, np.ndarray]:
    """cos(phi) = s.q1 and root = sqrt(lambda^2 - sin^2 phi) of Eqs. (14), (21).

    Per ERRATA "Numerics", sin^2(phi) is not formed as 1 - (s.q1)^2, which loses
    every digit at small lambda. It is |s x q1|^2: exact to rounding, and,
    unlike |s x q1|, differentiable at phi = 0 (the goal image has q1 = s), so
    AutoDiffXd gives finite derivatives there.
    """
    q1 = y.q1
    cos_phi = dot(y.s, q1)
    w = cross(y.s, q1)
    root = np.sqrt(y.lam**2 - dot(w, w))
    return cos_phi, root


def _marked_point_distance(y: ImageFeatures, radius: object) -> np.ndarray:
    """beta = |b| of Eq. (21) (ERRATA: Eq. 41 is misprinted)."""
    cos_phi, root = _phi_terms(y)
    return (radius / y.lam) * (cos_phi - root)


def camera_map_inverse(y: ImageFeatures | np.ndarray, radius: object) -> object:
    """The inverse camera map c^-1(y) of Eq. (23).

    Returns a ``RigidTransform`` of y's scalar type for a single y, or a
    (..., 4, 4) float array for a batch.
    """
    _check_radius(radius)
    y = validate_features(y)
    cos_phi, root = _phi_terms(y)
    lam = y.lam
    q1, s = y.q1, y.s
    d = col(radius / lam) * s
    r3 = (s - col(cos_phi - root) * q1) / col(lam)
    # Eq. (23) writes r2 ~ q2 - (r3.q2 / r3.q1) q1. Multiplied by r3.q1 > 0 this
    # is (r3.q1) q2 - (r3.q2) q1 = q3 x r3: the same direction without dividing
    # by r3.q1 = nu / |b|, which near the visibility boundary cost 7 digits.
    g = cross(y.q3, r3)
    r2 = g / col(norm(g))
    r1 = cross(r2, r3)
    R = np.stack([r1, r2, r3], axis=-1)
    if R.ndim == 2:
        T = _scalar_type(R)
        return RigidTransform_[T](RotationMatrix_[T](R), d)
    X = np.zeros(R.shape[:-2] + (4, 4), dtype=R.dtype)
    X[..., :3, :3] = R
    X[..., :3, 3] = d
    X[..., 3, 3] = 1.0
    return X


def _scalar_type(a: np.ndarray) -> type:
    if a.dtype != object:
        return float
    first = a.flat[0]
    if isinstance(first, AutoDiffXd):
        return AutoDiffXd
    return Expression


def image_jacobian(y: ImageFeatures | np.ndarray, radius: object) -> np.ndarray:
    """C(y) of Eq. (14), shape (..., 7, 6).

    Maps the right-trivialised velocity ``(omega, v)`` of ``X_CB`` (Eq. 11) to
    ``(xi, lambda_dot, s_dot)`` (Eqs. 12-13). beta = |b| of Eq. (21).
    """
    _check_radius(radius)
    y = validate_features(y)
    _, root = _phi_terms(y)
    lam, s = y.lam, y.s
    q1, q2, q3 = y.q1, y.q2, y.q3
    beta = _marked_point_distance(y, radius)
    delta = dot(s, q2) / root
    eye = np.eye(3)
    top_right = (mat(delta) * outer(q1, q3) - outer(q2, q3) + outer(q3, q2)) / mat(beta)
    top_left = np.broadcast_to(eye, top_right.shape).astype(top_right.dtype)
    lam_row = col(-(lam**2) / radius) * s
    zero = s * 0
    s_right = mat(lam / radius) * (eye - outer(s, s))
    top = np.concatenate([top_left, top_right], axis=-1)
    mid = np.concatenate([zero, lam_row], axis=-1)[..., None, :]
    bottom = np.concatenate([-hat(s), s_right], axis=-1)
    return np.concatenate([top, mid, bottom], axis=-2)


def image_jacobian_inverse(y: ImageFeatures | np.ndarray, radius: object) -> np.ndarray:
    """Tc^-1 = (C^T C)^-1 C^T of Eq. (15), shape (..., 6, 7).

    On the range of C (the 7-vectors whose s-part is orthogonal to s) this is the
    exact inverse of C: the paper's point is that T_y I is a 6-dimensional
    subspace of R^7, not that a least-squares fit is being made. For float
    input it is evaluated through the SVD (``np.linalg.pinv``, the same matrix
    for a full-column-rank C) because forming C^T C squares the condition
    number, which near the visibility boundary exceeds 1e10.
    """
    C = image_jacobian(y, radius)
    if C.dtype != object:
        return np.linalg.pinv(C)
    Ct = np.swapaxes(C, -1, -2)
    CtC = Ct @ C
    if C.ndim != 2:
        raise ValueError("object-dtype image_jacobian_inverse takes a single y, not a batch")
    return pm.inv(CtC) @ Ct

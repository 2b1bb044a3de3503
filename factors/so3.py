"""SO(3) helpers shared by every factor and estimator: skew, exp, log and the right Jacobian (and its inverse).

Each function takes one 3-vector (or 3x3 matrix) or a stack with any leading axes (..., 3), as jaxlie's SO3.exp
does. One 3-vector takes a fast path on Python floats: a DVL factor's linearisation calls skew three or four
times, and numpy's setup for a (3,) array costs more than the arithmetic. Hand-written rather than
scipy.spatial.transform.Rotation: the factors need skew and the right Jacobian, which scipy does not give, and
building a Rotation object costs more than the arithmetic on a single rotation. Conventions are GTSAM's Rot3:
Exp(phi) rotates by |phi| about phi, and J_r(phi) is defined by Exp(phi + d) = Exp(phi) Exp(J_r(phi) d) to first order.
"""

from __future__ import annotations

import math

import numpy as np

_EYE3 = np.eye(3)
_EYE3.setflags(write=False)
# rad: below, inv_right_jacobian's coefficient from its series (the closed form cancels)
_SMALL = 0.1


def skew(a: np.ndarray) -> np.ndarray:
    """[a]_x (..., 3, 3) of a (..., 3): [a]_x b = a x b."""
    if not (isinstance(a, np.ndarray) and a.ndim == 1):
        a = np.asarray(a, dtype=float)
    if a.shape == (3,):
        x, y, z = a.tolist()
        return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    out = np.zeros(a.shape[:-1] + (3, 3))
    x, y, z = a[..., 0], a[..., 1], a[..., 2]
    out[..., 0, 1], out[..., 0, 2] = -z, y
    out[..., 1, 0], out[..., 1, 2] = z, -x
    out[..., 2, 0], out[..., 2, 1] = -y, x
    return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b (..., 3); two 3-vectors written out (np.cross's axis handling costs more than the arithmetic)."""
    if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape == (3,) and b.shape == (3,):
        a0, a1, a2 = a.tolist()
        b0, b1, b2 = b.tolist()
        return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])
    return np.asarray(np.cross(a, b))


def rotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R v (..., 3) for R (..., 3, 3) and v (..., 3), broadcast (GTSAM's Rot3.rotate)."""
    if v.ndim == 1 and R.ndim == 2:
        return R @ v
    return np.einsum("...ij,...j->...i", R, v)


def unrotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R^T v (..., 3) for R (..., 3, 3) and v (..., 3), broadcast (GTSAM's Rot3.unrotate)."""
    if v.ndim == 1 and R.ndim == 2:
        return v @ R
    return np.einsum("...ji,...j->...i", R, v)


def _theta2(phi: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", phi, phi)


def _rodrigues(phi: np.ndarray, jacobian: bool) -> np.ndarray:
    """I + a(theta) K + b(theta) K^2, K = [phi]_x: Exp(phi) (a = sin/theta, b = (1 - cos)/theta^2; their limits 1,
    1/2 below 1e-8 rad) or with jacobian J_r(phi) (a = -(1 - cos)/theta^2, b = (theta - sin)/theta^3; -1/2, 1/6
    below 1e-6 rad)."""
    small_at, a_small, b_small = (1e-6, -0.5, 1.0 / 6.0) if jacobian else (1e-8, 1.0, 0.5)
    phi = np.asarray(phi, dtype=float)
    K = skew(phi)
    if phi.shape == (3,):
        theta2 = float(phi @ phi)
        theta = theta2**0.5
        if theta < small_at:
            return _EYE3 + a_small * K + b_small * (K @ K)
        sin, cos = math.sin(theta), math.cos(theta)
        a = -(1.0 - cos) / theta2 if jacobian else sin / theta
        b = (theta - sin) / (theta2 * theta) if jacobian else (1.0 - cos) / theta2
        return _EYE3 + a * K + b * (K @ K)
    t2 = _theta2(phi)
    small = t2 < small_at**2
    ts2 = np.where(small, 1.0, t2)
    ts = np.sqrt(ts2)
    sn, cs = np.sin(ts), np.cos(ts)
    an = np.where(small, a_small, -(1.0 - cs) / ts2 if jacobian else sn / ts)
    bn = np.where(small, b_small, (ts - sn) / (ts2 * ts) if jacobian else (1.0 - cs) / ts2)
    return _EYE3 + an[..., None, None] * K + bn[..., None, None] * (K @ K)


def exp(phi: np.ndarray) -> np.ndarray:
    """Exp(phi) (..., 3, 3) of rotation vectors phi (..., 3), rad: Rodrigues' formula, its second-order series
    below 1e-8 rad (exact to rounding there)."""
    return _rodrigues(phi, False)


def right_jacobian(phi: np.ndarray) -> np.ndarray:
    """J_r(phi) (..., 3, 3): Exp(phi + d) = Exp(phi) Exp(J_r(phi) d) to first order; I - K / 2 + K^2 / 6 below
    1e-6 rad."""
    return _rodrigues(phi, True)


def inv_right_jacobian(phi: np.ndarray) -> np.ndarray:
    """J_r(phi)^-1 (..., 3, 3) = I + K / 2 + d(theta) K^2, d = 1/theta^2 - (1 + cos)/(2 theta sin), its series
    below 0.1 rad."""
    phi = np.asarray(phi, dtype=float)
    t2 = _theta2(phi)
    t = np.sqrt(t2)
    small = t < _SMALL
    ts = np.where(small, 1.0, t)
    d = np.where(
        small,
        1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0,
        1.0 / ts**2 - (1.0 + np.cos(ts)) / (2.0 * ts * np.sin(ts)),
    )
    K = skew(phi)
    return _EYE3 + 0.5 * K + np.asarray(d)[..., None, None] * (K @ K)


def log(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices R (..., 3, 3), rad; exact near 0 and near pi."""
    R = np.asarray(R, dtype=float)
    lead = R.shape[:-2]
    R = R.reshape(-1, 3, 3)
    w = 0.5 * np.stack(
        [R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1
    )
    s = np.sqrt(_theta2(w))
    c = 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0)
    theta = np.arctan2(s, c)
    small = s < 1e-8
    scale = np.where(small, 1.0 + theta**2 / 6.0, theta / np.where(small, 1.0, s))
    out = w * scale[:, None]
    near_pi = c < -0.99  # sin(theta) small beside pi: the axis from the symmetric part
    for n in np.flatnonzero(near_pi).tolist():
        # symmetric part: cos I + (1 - cos) u u^T
        uu = (0.5 * (R[n] + R[n].T) - c[n] * _EYE3) / (1.0 - c[n])
        k = int(np.argmax(np.diag(uu)))
        u = uu[:, k] / np.sqrt(uu[k, k])
        u /= np.linalg.norm(u)
        if u @ w[n] < 0:  # (sin theta u: the sign, where theta is not exactly pi)
            u = -u
        out[n] = u * theta[n]
    return out.reshape(lead + (3,))

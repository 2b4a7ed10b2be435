"""Preconditioned conjugate gradients, written once for every backend.

:func:`conjugate_gradients` works over three small objects:

- an operator with ``apply(x, out)`` (``out = A x``) and, optionally, a fused
  ``apply_dot(x, out)`` that also returns ``x . out``;
- a preconditioner with ``apply(r)`` returning ``z ~ A^-1 r`` and, optionally, a fused
  ``apply_dot(r)`` returning ``(z, r . z)``; one that returns the same work array every
  call says so with ``reuses_output = True`` (CG then copies z where it keeps it);
- vector operations (:class:`ArrayOps`: array expressions; a backend may pass fused kernels
  with the same methods).

The defaults of the optional fused methods are the plain two-step versions, so a new
operator or preconditioner needs only ``apply``. The models are pyamg's
``krylov.cg(A, b, x0, tol, maxiter, M, callback, residuals)`` and muGrid's
``conjugate_gradients`` (one CG over a Hessian product and a preconditioner).

The recursive residual drives the iteration; when it reaches ``tol`` the true residual
``||b - A x|| / ||b||`` is computed and CG restarts from ``x`` if that is still above
``tol`` (round-off drift near convergence), at most ``max_restarts`` times. A warm start is
first scaled by the energy-optimal factor ``c = (b . x0) / (x0 . A x0)`` (never worse than
``x0`` in the A-norm; one operator application).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

__all__ = ["conjugate_gradients", "ArrayOps", "CGOutcome", "LinearOperator", "Preconditioner"]


class LinearOperator(Protocol):
    """``apply(x, out)`` writes ``A x`` into ``out`` (symmetric positive semi-definite A)."""

    def apply(self, x: Any, out: Any) -> None: ...


class Preconditioner(Protocol):
    """``apply(r)`` returns ``z``, an approximation of ``A^+ r`` (symmetric positive)."""

    def apply(self, r: Any) -> Any: ...


class ArrayOps:
    """Vector operations of CG as array expressions (numpy arrays).

    A backend with fused kernels passes an object with the same methods.
    """

    def dot(self, a: np.ndarray, b: np.ndarray) -> float:
        """``a . b`` in float64."""
        return float(np.dot(a.ravel(), b.ravel()))

    def update(self, x: np.ndarray, r: np.ndarray, p: np.ndarray, q: np.ndarray,
               alpha: float) -> float:
        """``x += alpha p``, ``r -= alpha q``; returns ``r . r``."""
        a = x.dtype.type(alpha)
        x += a * p
        r -= a * q
        return self.dot(r, r)

    def direction(self, p: np.ndarray, z: np.ndarray, beta: float) -> None:
        """``p = z + beta p`` in place."""
        p *= p.dtype.type(beta)
        p += z

    def residual(self, operator: LinearOperator, b: np.ndarray, x: np.ndarray,
                 out: np.ndarray) -> float:
        """``out = b - A x``; returns ``||out||^2``."""
        operator.apply(x, out)
        np.subtract(b, out, out=out)
        return self.dot(out, out)

    def scale(self, x: np.ndarray, c: float) -> None:
        """``x *= c`` in place."""
        x *= x.dtype.type(c)

    def is_zero(self, x: np.ndarray) -> bool:
        return not np.any(x)

    def like(self, z: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``z`` in the precision of ``x`` (itself when it already is)."""
        return z if z.dtype == x.dtype else z.astype(x.dtype)

    def empty_like(self, x: np.ndarray) -> np.ndarray:
        """A work vector of the shape and precision of ``x``."""
        return np.empty_like(x)


class CGOutcome:
    """Iterations, residual history (relative; the last entry is the true residual), the
    final true relative residual and the number of restarts of one CG solve."""

    __slots__ = ("iterations", "history", "residual", "restarts")

    def __init__(self, iterations: int, history: list[float], residual: float,
                 restarts: int) -> None:
        self.iterations = iterations
        self.history = history
        self.residual = residual
        self.restarts = restarts


def _apply_dot(operator: Any, x: Any, out: Any, ops: Any) -> float:
    fused = getattr(operator, "apply_dot", None)
    if fused is not None:
        return float(fused(x, out))
    operator.apply(x, out)
    return ops.dot(x, out)


def _precondition(preconditioner: Any, r: Any, ops: Any) -> tuple[Any, float]:
    fused = getattr(preconditioner, "apply_dot", None)
    if fused is not None:
        z, rz = fused(r)
        return z, float(rz)
    z = preconditioner.apply(r)
    return z, ops.dot(r, z)


def conjugate_gradients(operator: Any, b: Any, x: Any, *, tol: float, maxiter: int,
                        preconditioner: Any,
                        callback: Callable[[int, float], None] | None = None,
                        residuals: list[float] | None = None, ops: Any = None,
                        project: Callable[[Any], None] | None = None,
                        max_restarts: int = 5) -> CGOutcome:
    """Solve ``A x = b`` in place from the start ``x`` by preconditioned CG.

    Parameters
    ----------
    operator : object with ``apply(x, out)``
        The symmetric positive (semi-)definite operator A.
    b : array
        Right-hand side (in the range of A).
    x : array
        Start on entry, solution on return (its dtype is the CG vectors' precision).
    tol : float
        Relative residual ``||b - A x|| / ||b||`` to reach (checked on the true residual).
    maxiter : int
        Iterations at most (over all restarts).
    preconditioner : object with ``apply(r)``
        Symmetric positive preconditioner.
    callback : callable, optional
        ``callback(iteration, relative_residual)`` after every iteration (recursive residual).
    residuals : list, optional
        Filled with the relative residual history, as pyamg's ``residuals`` argument.
    ops : ArrayOps-like, optional
        Vector operations (default :class:`ArrayOps`).
    project : callable, optional
        Applied in place to every residual (removes the null space of a singular A, e.g.
        the mean of each connected cluster).
    max_restarts : int
        Restarts from the current iterate allowed when the true residual is above ``tol``.

    Returns
    -------
    CGOutcome
    """
    ops = ArrayOps() if ops is None else ops
    history: list[float] = [] if residuals is None else residuals
    history.clear()
    normb = math.sqrt(ops.dot(b, b))
    if normb == 0.0:  # A x = 0: x = 0 solves it exactly
        ops.scale(x, 0.0)
        history.append(0.0)
        return CGOutcome(0, history, 0.0, 0)
    r = ops.empty_like(x)
    q = ops.empty_like(x)
    if not ops.is_zero(x):
        xax = _apply_dot(operator, x, q, ops)
        if xax > 0.0:
            ops.scale(x, ops.dot(b, x) / xax)
    true_res = math.sqrt(ops.residual(operator, b, x, r)) / normb
    history.append(true_res)
    it = restarts = 0
    while true_res > tol and it < maxiter and restarts <= max_restarts:
        if project is not None:
            project(r)
        z, rz = _precondition(preconditioner, r, ops)
        p = ops.like(z, x)  # p keeps the CG precision
        if p is z and getattr(preconditioner, "reuses_output", False):
            p = p.copy()  # the preconditioner writes its next z into the same array
        del z
        rec = true_res
        while it < maxiter:
            pq = _apply_dot(operator, p, q, ops)
            if not pq > 0.0 or not rz > 0.0:
                break  # breakdown: exact solution in the Krylov space or loss of definiteness
            rr = ops.update(x, r, p, q, rz / pq)
            it += 1
            if project is not None:
                project(r)
                rr = ops.dot(r, r)
            rec = math.sqrt(rr) / normb
            history.append(rec)
            if callback is not None:
                callback(it, rec)
            if rec <= tol:
                break
            z, rz_new = _precondition(preconditioner, r, ops)
            beta = rz_new / rz
            rz = rz_new
            ops.direction(p, z, beta)
            del z
        del p
        true_res = math.sqrt(ops.residual(operator, b, x, r)) / normb
        if true_res > tol and (rec <= tol or it < maxiter):
            restarts += 1  # drift of the recursive residual, or a breakdown above tol
    history[-1] = true_res
    return CGOutcome(it, history, true_res, restarts)

"""Preconditioned conjugate gradients, written once for every backend.

:func:`conjugate_gradients` works over three small objects:

- an operator with ``apply(x, out)`` (``out = A x``) and, optionally, a fused
  ``apply_dot(x, out)`` that also returns ``x . out``, and ``apply_dot_block(xs, outs)``
  (several fields in one pass, returning their dots);
- a preconditioner with ``apply(r)`` returning ``z ~ A^-1 r`` and, optionally, a fused
  ``apply_dot(r)`` returning ``(z, r . z)`` (CG copies z into its own search direction, so a
  preconditioner may return the same work array every call);
- vector operations (:class:`ArrayOps`: array expressions; a backend may pass fused kernels
  with the same methods; ``empty_like`` sets the work vectors' precision).

The defaults of the optional fused methods are the plain two-step versions, so a new
operator or preconditioner needs only ``apply``. The models are pyamg's
``krylov.cg(A, b, x0, tol, maxiter, M, callback, residuals)`` and muGrid's
``conjugate_gradients`` (one CG over a Hessian product and a preconditioner).

The CG is one generator (``_cg_steps``) that asks its driver for every operator product:
:func:`conjugate_gradients` drives one, :func:`block_conjugate_gradients` drives one per
load case in lockstep and serves their products of an iteration with one
``apply_dot_block`` call, so a block has the iterates of single solves.

The recursive residual drives the iteration; when it reaches ``tol`` the true residual
``||b - A x|| / ||b||`` is computed and CG restarts from ``x`` if that is still above
``tol`` (round-off drift near convergence), at most ``max_restarts`` times. With
``true_operator`` and ``replace_below`` (mixed precision) the true residual also replaces
the recursive one whenever that has fallen by the factor ``replace_below`` (reliable
updates), and CG goes on from there. A warm start is first scaled by the energy-optimal
factor ``c = (b . x0) / (x0 . A x0)`` (never worse than ``x0`` in the A-norm; one operator
application).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from typing import Any, Protocol

import numpy as np

__all__ = ["conjugate_gradients", "block_conjugate_gradients", "ArrayOps", "CGOutcome",
           "LinearOperator", "Preconditioner"]


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

    def copy_into(self, dst: np.ndarray, src: np.ndarray) -> None:
        """``dst[...] = src`` (rounded to dst's precision)."""
        dst[...] = src

    def empty_like(self, x: np.ndarray) -> np.ndarray:
        """A work vector of the shape and precision of ``x``."""
        return np.empty_like(x)


class CGOutcome:
    """Iterations, residual history (relative; the last entry is the true residual), the
    final true relative residual, the number of restarts and of residual replacements of
    one CG solve."""

    __slots__ = ("iterations", "history", "residual", "restarts", "replacements")

    def __init__(self, iterations: int, history: list[float], residual: float,
                 restarts: int, replacements: int = 0) -> None:
        self.iterations = iterations
        self.history = history
        self.residual = residual
        self.restarts = restarts
        self.replacements = replacements


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


#: What a CG in progress asks of its driver: ``q = A p`` and ``p . q`` back.
_Steps = Generator[tuple[Any, Any], float, CGOutcome]


def _cg_steps(b: Any, x: Any, *, tol: float, maxiter: int, preconditioner: Any, ops: Any,
              true_operator: Any, callback: Callable[[int, float], None] | None,
              history: list[float], project: Callable[[Any], None] | None,
              max_restarts: int, replace_below: float | None) -> _Steps:
    """One CG solve as a generator: it yields ``(p, q)`` wherever it needs ``q = A p`` and
    receives ``p . q``; everything else (the preconditioner, the vector operations, the
    true residuals with ``true_operator``) it does itself. Its return value is the
    :class:`CGOutcome`. Driven by :func:`conjugate_gradients` (one) and
    :func:`block_conjugate_gradients` (several in lockstep, one operator pass for all)."""
    history.clear()
    normb = math.sqrt(ops.dot(b, b))
    if normb == 0.0:  # A x = 0: x = 0 solves it exactly
        ops.scale(x, 0.0)
        history.append(0.0)
        return CGOutcome(0, history, 0.0, 0)
    r = ops.empty_like(x)  # the work vectors: the ops' working precision
    q = ops.empty_like(x)
    p = ops.empty_like(x)
    if not ops.is_zero(x):
        xax = _apply_dot(true_operator, x, q, ops)
        if xax > 0.0:
            ops.scale(x, ops.dot(b, x) / xax)
    true_res = math.sqrt(ops.residual(true_operator, b, x, r)) / normb
    history.append(true_res)
    it = restarts = replacements = 0
    while true_res > tol and it < maxiter and restarts <= max_restarts:
        if project is not None:
            project(r)
        z, rz = _precondition(preconditioner, r, ops)
        ops.copy_into(p, z)
        del z
        rec = true_res
        last_true = true_res
        while it < maxiter:
            pq = yield p, q
            if not pq > 0.0 or not rz > 0.0:
                break  # breakdown: exact solution in the Krylov space or loss of definiteness
            rr = ops.update(x, r, p, q, rz / pq)
            it += 1
            if project is not None:
                project(r)
                rr = ops.dot(r, r)
            rec = math.sqrt(rr) / normb
            if replace_below is not None and (rec <= tol or rec < replace_below * last_true):
                # reliable update: the true residual of x replaces the recursive one
                rec = last_true = math.sqrt(ops.residual(true_operator, b, x, r)) / normb
                replacements += 1
                if project is not None:
                    project(r)
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
        true_res = math.sqrt(ops.residual(true_operator, b, x, r)) / normb
        if true_res > tol and (rec <= tol or it < maxiter):
            restarts += 1  # drift of the recursive residual, or a breakdown above tol
    history[-1] = true_res
    return CGOutcome(it, history, true_res, restarts, replacements)


def _check_replace(replace_below: float | None) -> float | None:
    if replace_below is not None and not 0.0 < replace_below < 1.0:
        raise ValueError(f"replace_below: expected a factor in (0, 1), got {replace_below!r}")
    return replace_below


def conjugate_gradients(operator: Any, b: Any, x: Any, *, tol: float, maxiter: int,
                        preconditioner: Any,
                        callback: Callable[[int, float], None] | None = None,
                        residuals: list[float] | None = None, ops: Any = None,
                        project: Callable[[Any], None] | None = None,
                        max_restarts: int = 5, true_operator: Any = None,
                        replace_below: float | None = None) -> CGOutcome:
    """Solve ``A x = b`` in place from the start ``x`` by preconditioned CG.

    Parameters
    ----------
    operator : object with ``apply(x, out)``
        The symmetric positive (semi-)definite operator A that CG iterates with.
    b : array
        Right-hand side (in the range of A).
    x : array
        Start on entry, solution on return (its dtype is the solution's precision).
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
        Vector operations (default :class:`ArrayOps`); ``ops.empty_like(x)`` sets the
        precision of the work vectors r, p, q.
    project : callable, optional
        Applied in place to every residual (removes the null space of a singular A, e.g.
        the mean of each connected cluster).
    max_restarts : int
        Restarts from the current iterate allowed when the true residual is above ``tol``.
    true_operator : object with ``apply(x, out)``, optional
        The operator of the true residuals (default ``operator``): mixed precision iterates
        with a float32 ``operator`` and float32 work vectors, and checks (and replaces) the
        residual with the float64 one on the float64 ``x``.
    replace_below : float in (0, 1), optional
        Reliable updates: whenever the recursive residual falls below this factor times the
        last true one (or below ``tol``), the true residual replaces it and CG goes on
        (None: never, the plain CG).

    Returns
    -------
    CGOutcome
    """
    ops = ArrayOps() if ops is None else ops
    steps = _cg_steps(b, x, tol=tol, maxiter=maxiter, preconditioner=preconditioner,
                      ops=ops,
                      true_operator=operator if true_operator is None else true_operator,
                      callback=callback, history=[] if residuals is None else residuals,
                      project=project, max_restarts=max_restarts,
                      replace_below=_check_replace(replace_below))
    return _drive([steps], operator, ops)[0]


def block_conjugate_gradients(operator: Any, loads: Sequence[Any], starts: Sequence[Any], *,
                              tol: float, maxiter: int, preconditioner: Any,
                              callback: Callable[[int, int, float], None] | None = None,
                              ops: Any = None, project: Callable[[Any], None] | None = None,
                              max_restarts: int = 5, true_operator: Any = None,
                              replace_below: float | None = None) -> list[CGOutcome]:
    """Solve ``A x_c = b_c`` for several right-hand sides in lockstep.

    Each right-hand side runs the CG of :func:`conjugate_gradients` (the same arithmetic,
    so the same iterates); their operator products of one iteration are one call of
    ``operator.apply_dot_block(ps, qs)`` (``qs[c] = A ps[c]``, returning the ``ps[c] .
    qs[c]``) where the operator has it, so that each conductance is read once for all of
    them. Load cases that converge drop out; the others go on.

    Parameters
    ----------
    loads, starts : sequences of arrays
        Right-hand sides and starts (solutions on return), one per load case.
    callback : callable, optional
        ``callback(case, iteration, relative_residual)`` with ``case`` the position in
        ``loads``.
    operator, tol, maxiter, preconditioner, ops, project, max_restarts, true_operator,
    replace_below
        As :func:`conjugate_gradients` (``maxiter`` per load case).

    Returns
    -------
    list of CGOutcome
        One per load case.
    """
    if len(loads) != len(starts):
        raise ValueError(f"starts: expected one start per load ({len(loads)}), got "
                         f"{len(starts)}")
    ops = ArrayOps() if ops is None else ops
    true_operator = operator if true_operator is None else true_operator
    replace_below = _check_replace(replace_below)
    steps = []
    for c, (b, x) in enumerate(zip(loads, starts)):
        step = None if callback is None else (lambda it, res, _c=c: callback(_c, it, res))
        steps.append(_cg_steps(b, x, tol=tol, maxiter=maxiter, preconditioner=preconditioner,
                               ops=ops, true_operator=true_operator, callback=step,
                               history=[], project=project, max_restarts=max_restarts,
                               replace_below=replace_below))
    return _drive(steps, operator, ops)


def _advance(step: _Steps, value: float | None) -> tuple[tuple[Any, Any] | None,
                                                         CGOutcome | None]:
    """The next request of a CG in progress, or its outcome when it is done."""
    try:
        return (next(step) if value is None else step.send(value)), None
    except StopIteration as done:
        return None, done.value


def _drive(steps: list[_Steps], operator: Any, ops: Any) -> list[CGOutcome]:
    """Run CGs to the end, serving their operator products together."""
    outcomes: list[CGOutcome | None] = [None] * len(steps)
    waiting: dict[int, tuple[Any, Any]] = {}
    for c, step in enumerate(steps):
        request, outcomes[c] = _advance(step, None)
        if request is not None:
            waiting[c] = request
    block = getattr(operator, "apply_dot_block", None)
    while waiting:
        cases = list(waiting)
        if block is not None and len(cases) > 1:
            dots = [float(d) for d in block([waiting[c][0] for c in cases],
                                            [waiting[c][1] for c in cases])]
        else:
            dots = [_apply_dot(operator, *waiting[c], ops) for c in cases]
        for c, pq in zip(cases, dots):
            request, outcomes[c] = _advance(steps[c], pq)
            if request is None:
                del waiting[c]
            else:
                waiting[c] = request
    return outcomes  # type: ignore[return-value]

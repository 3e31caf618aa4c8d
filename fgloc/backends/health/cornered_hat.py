"""The N-cornered hat: each source's own noise variance from the variances of the pairs' differences
(least squares, non-negative), solved in scalar Python (a few sources, at every block)."""

from __future__ import annotations

import math

import numpy as np

_HAT_SYSTEMS: dict[tuple[int, tuple[tuple[int, int], ...]], tuple] = {}


_GROUPS: dict[tuple[tuple[str, str], ...], list[tuple[list[str], dict[str, int]]]] = {}


def cornered_hat(names: list[str], pairs: dict[tuple[str, str], float],
                 prior: dict[str, float], n_eff: dict[tuple[str, str], float] | None = None,
                 unresolved: str = "prior") -> dict[str, float]:
    """Per-source variances ``v`` with ``v_a + v_b ~= pairs[(a, b)]``, ``v >= 0`` (least squares).

    A source the pairs cannot separate from another (two sources alone, or a third source far
    noisier than the two: its pairs' statistics are too uncertain, judged from ``n_eff``
    blocks each) keeps its prior (claimed) variance, but never more than any pair it is in
    allows (``v_a <= pairs[(a, b)]``): evidence that it is better than claimed is used,
    evidence of which of two is worse is not invented.

    Each connected group of sources is a least-squares problem ``A v = y`` whose rows hold two
    ones (a pair): a handful of unknowns, solved in scalar maths through its normal equations
    ``A^T A`` (integer entries: a group is separable exactly when they are regular, i.e. its pairs
    close an odd cycle); the standard deviations of the solution from ``(A^T A)^-1 A^T`` and the
    pairs' own.  Only a solution with a negative part goes through the non-negative active set
    (:func:`_nnls_normal`).  (numpy's SVD,
    pseudo-inverse and least squares on these 3x3 to 6x4 systems cost ~0.25 ms per call, the
    arbiter solves two or three a second.)
    """
    if not pairs:
        return {}
    n_eff = n_eff or {}
    plist = tuple(pairs)
    groups = _GROUPS.get(plist)
    if groups is None:  # the connected groups and each one's source indices: once per pair set
        srcs = sorted({s for p in pairs for s in p})
        groups = [(members, {s: i for i, s in enumerate(members)}) for members in _components(srcs, list(plist))]
        if len(_GROUPS) > 256:
            _GROUPS.clear()
        _GROUPS[plist] = groups
    out: dict[str, float] = {}
    for members, loc in groups:
        n = len(members)
        rows = [(loc[a], loc[b], float(pairs[(a, b)]), float(pairs[(a, b)])
                 * math.sqrt(2.0 / max(n_eff.get((a, b), 1e9), 1.0))) for (a, b) in plist if a in loc]
        rhs = [0.0] * n
        ub = [math.inf] * n
        for a, b, yv, _ in rows:
            rhs[a] += yv
            rhs[b] += yv
            ub[a] = min(ub[a], yv)
            ub[b] = min(ub[b], yv)
        N, inv, wsq = _hat_system(n, tuple((a, b) for a, b, _, _ in rows))
        v = [math.nan] * n
        if inv is not None:
            v = [sum(inv[i][j] * rhs[j] for j in range(n)) for i in range(n)]
            if not all(x > 0.0 for x in v):
                v = _nnls_normal(N, rhs, len(rows))
            sd2 = [0.0] * n
            for (_, _, _, sig), wr in zip(rows, wsq, strict=True):
                s2 = sig * sig
                for m in range(n):
                    sd2[m] += wr[m] * s2
            for m, s_name in enumerate(members):
                if math.sqrt(max(sd2[m], 0.0)) > 0.5 * max(v[m], prior.get(s_name, 0.0)):
                    v[m] = math.nan  # not resolved
        for m, s_name in enumerate(members):
            if math.isfinite(v[m]):
                val = v[m]
            elif unresolved == "prior":
                val = prior.get(s_name, 0.0)
            else:
                continue
            out[s_name] = max(min(val, ub[m]), 0.0)
    return out


def _hat_system(n: int, rows: tuple[tuple[int, int], ...]) -> tuple[list[list[float]], list[list[float]] | None,
                                                                   list[list[float]]]:
    """A pair set's normal matrix ``N = A^T A`` (``rows``: each pair's two source indices), its
    inverse (None when singular) and per row the squared weights ``(inv[m][a] + inv[m][b])^2`` of
    its pair in each source's solution: they depend on which pairs there are only, not on their
    values (the arbiter solves the same few sets once a second), so they are made once per set."""
    key = (n, rows)
    got = _HAT_SYSTEMS.get(key)
    if got is None:
        N = [[0.0] * n for _ in range(n)]
        for a, b in rows:
            N[a][a] += 1.0
            N[b][b] += 1.0
            N[a][b] += 1.0
            N[b][a] += 1.0
        inv = _spd_inverse(N)
        wsq = [[(inv[m][a] + inv[m][b]) * (inv[m][a] + inv[m][b]) for m in range(n)] for a, b in rows] \
            if inv is not None else []
        if len(_HAT_SYSTEMS) > 256:
            _HAT_SYSTEMS.clear()
        got = _HAT_SYSTEMS[key] = (N, inv, wsq)
    return got


def _nnls_normal(N: list[list[float]], rhs: list[float], n_rows: int) -> list[float]:
    """``argmin |A v - y|`` with ``v >= 0`` (Lawson-Hanson's active set, as scipy.optimize's ``nnls``;
    importing scipy.optimize cost 0.3-1.3 s of CPU per process) on the normal equations ``N = A^T A``,
    ``rhs = A^T y`` of a full-column-rank ``A`` with ``n_rows`` rows of zeros and ones, in scalar
    maths: each step's least squares on the active columns is ``N_SS z_S = rhs_S``."""
    n = len(N)
    x = [0.0] * n
    z = [0.0] * n
    active = [False] * n
    tol = 10.0 * _EPS * max(N[i][i] for i in range(n)) * max(n_rows, n)
    for _ in range(3 * n + 3):
        w = [rhs[i] - sum(N[i][j] * x[j] for j in range(n)) for i in range(n)]
        free = [i for i in range(n) if not active[i]]
        if not free:
            break
        j = max(free, key=lambda i: w[i])  # the first of equal maxima, as np.argmax
        if w[j] <= tol:
            break
        active[j] = True
        for _ in range(3 * n + 3):
            S = [i for i in range(n) if active[i]]
            zs = _spd_solve([[N[a][b] for b in S] for a in S], [rhs[a] for a in S])
            z = [0.0] * n
            for a, za in zip(S, zs, strict=True):
                z[a] = za
            if all(za > 0.0 for za in zs):
                break
            alpha = min(x[i] / (x[i] - z[i]) for i in S if z[i] <= 0.0)
            x = [xi + alpha * (zi - xi) for xi, zi in zip(x, z, strict=True)]
            active = [active[i] and x[i] > tol for i in range(n)]
        x = z
    return [max(xi, 0.0) for xi in x]


_EPS = float(np.finfo(float).eps)


def _cholesky(N: list[list[float]], tol: float | None) -> list[list[float]] | None:
    """The lower Cholesky factor of a small symmetric matrix (scalar maths).  ``tol`` None: a pivot
    is clamped at 1e-300 (positive definite by construction); else None when one is not above ``tol``."""
    n = len(N)
    L = [[0.0] * n for _ in range(n)]
    for j in range(n):
        d = N[j][j] - sum(L[j][k] * L[j][k] for k in range(j))
        if tol is None:
            d = max(d, 1e-300)
        elif not d > tol:
            return None
        L[j][j] = math.sqrt(d)
        for i in range(j + 1, n):
            L[i][j] = (N[i][j] - sum(L[i][k] * L[j][k] for k in range(j))) / L[j][j]
    return L


def _spd_solve(N: list[list[float]], b: list[float]) -> list[float]:
    """``N^-1 b`` for a small symmetric positive definite ``N`` (Cholesky, scalar maths)."""
    n = len(N)
    L = _cholesky(N, None)
    assert L is not None
    y = [0.0] * n
    for i in range(n):
        y[i] = (b[i] - sum(L[i][k] * y[k] for k in range(i))) / L[i][i]
    out = [0.0] * n
    for i in reversed(range(n)):
        out[i] = (y[i] - sum(L[k][i] * out[k] for k in range(i + 1, n))) / L[i][i]
    return out


def _spd_inverse(N: list[list[float]]) -> list[list[float]] | None:
    """The inverse of a small symmetric positive semi-definite matrix (Cholesky, scalar maths),
    None when it is singular (a pivot below 1e-9 of the largest diagonal entry)."""
    n = len(N)
    L = _cholesky(N, 1e-9 * max(N[i][i] for i in range(n)))
    if L is None:
        return None
    # L^-1 by forward substitution, then N^-1 = L^-T L^-1
    Li = [[0.0] * n for _ in range(n)]
    for i in range(n):
        Li[i][i] = 1.0 / L[i][i]
        for j in range(i):
            Li[i][j] = -sum(L[i][k] * Li[k][j] for k in range(j, i)) / L[i][i]
    return [[sum(Li[k][i] * Li[k][j] for k in range(max(i, j), n)) for j in range(n)] for i in range(n)]


def _components(srcs: list[str], pairs: list[tuple[str, str]]) -> list[list[str]]:
    parent = {s: s for s in srcs}

    def find(s: str) -> str:
        while parent[s] != s:
            parent[s] = parent[parent[s]]
            s = parent[s]
        return s

    for a, b in pairs:
        parent[find(a)] = find(b)
    groups: dict[str, list[str]] = {}
    for s in srcs:
        groups.setdefault(find(s), []).append(s)
    return list(groups.values())

"""The path-coordinate NLP as one function with its derivatives, named as CasADi's
``external`` finds them in a library: ``path_nlp`` (x, p) → (f, g), its Jacobian
``jac_path_nlp``, its reverse derivative ``adj1_path_nlp`` and that one's Jacobian
``jac_adj1_path_nlp``, whose (x, x) block is the Lagrangian's Hessian.

FATROP's CasADi plugin takes no derivative functions of its own (IPOPT's takes grad_f, jac_g
and hess_lag); it differentiates the NLP it is given. Given a call of ``path_nlp`` loaded
from a compiled library, it reads exactly these four, which here are the assembled
intervals' and landmarks' derivatives (:mod:`~spm_opt.planners.ocp.path_assembly`) compiled
with them, not CasADi's derivatives of the expanded NLP. Nothing differentiates in p (the
solver is told not to compute p's multipliers): every derivative in p is given as zero.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from spm_opt.planners.ocp.assembly import Scatter
from spm_opt.planners.ocp.path_assembly import AssembledPathNlp

ORACLE = "path_nlp"
NAMES = (ORACLE, f"jac_{ORACLE}", f"adj1_{ORACLE}", f"jac_adj1_{ORACLE}")
"""The function and the derivatives CasADi looks up by these names."""


def oracle_functions(nlp: AssembledPathNlp) -> list[ca.Function]:
    """The functions of :data:`NAMES` for ``nlp``, in MX over its interval and landmark
    functions (which code generation compiles with them)."""
    x, p = nlp.problem["x"], nlp.problem["p"]
    n, n_g, n_p = x.numel(), nlp.problem["g"].numel(), p.numel()
    f, g = ca.MX.sym("f"), ca.MX.sym("g", n_g)
    _, gradient = nlp.derivatives["grad_f"](x, p)
    jacobian_function, hessian_function = nlp.derivatives["jac_g"], nlp.derivatives["hess_lag"]
    _, jacobian = jacobian_function(x, p)
    transposed = _transposed(jacobian_function.sparsity_out(1))(jacobian.nz[:])
    sigma, lam = ca.MX.sym("adj_f"), ca.MX.sym("adj_g", n_g)
    upper = hessian_function(x, p, sigma, lam)
    hessian = _symmetric(hessian_function.sparsity_out(0))(upper.nz[:])
    adjoint_x, adjoint_p = ca.MX.sym("out_adj_x", n), ca.MX.sym("out_adj_p", n_p)
    jac, adj1, jac_adj1 = NAMES[1:]
    return [
        ca.Function(ORACLE, [x, p], [nlp.problem["f"], nlp.problem["g"]]),
        ca.Function(jac, [x, p, f, g], [gradient.T, ca.MX(1, n_p), jacobian, ca.MX(n_g, n_p)]),
        ca.Function(
            adj1, [x, p, f, g, sigma, lam], [gradient * sigma + transposed @ lam, ca.MX(n_p, 1)]
        ),
        ca.Function(
            jac_adj1,
            [x, p, f, g, sigma, lam, adjoint_x, adjoint_p],
            [
                *(hessian, ca.MX(n, n_p), ca.MX(n, 1), ca.MX(n, n_g), gradient, transposed),
                *(ca.MX(n_p, n), ca.MX(n_p, n_p), ca.MX(n_p, 1), ca.MX(n_p, n_g)),
                *(ca.MX(n_p, 1), ca.MX(n_p, n_g)),
            ],
        ),
    ]


def _transposed(pattern: ca.Sparsity) -> Scatter:
    """A matrix of ``pattern``'s nonzeros to its transpose."""
    rows, columns = (np.asarray(v) for v in pattern.get_triplet())
    count = len(rows)
    return Scatter(columns, rows, np.ones(count), np.arange(count), pattern.shape[::-1], count)


def _symmetric(pattern: ca.Sparsity) -> Scatter:
    """An upper triangle of ``pattern``'s nonzeros to the whole symmetric matrix."""
    rows, columns = (np.asarray(v) for v in pattern.get_triplet())
    below = rows != columns
    return Scatter(
        np.concatenate([rows, columns[below]]),
        np.concatenate([columns, rows[below]]),
        np.ones(len(rows) + np.count_nonzero(below)),
        np.concatenate([np.arange(len(rows)), np.flatnonzero(below)]),
        pattern.shape,
        len(rows),
    )

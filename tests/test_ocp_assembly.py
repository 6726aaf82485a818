"""The NLP assembled from one interval's derivatives equals CasADi's own derivatives of the
same NLP written plainly (the interval function mapped over the grid), with and without
the torque rows."""

import casadi as ca
import numpy as np
import pytest

from spm_opt.model.joint_torque import range_key
from spm_opt.planners.ocp import nlp
from spm_opt.planners.ocp.assembly import assemble, interval_functions
from spm_opt.planners.ocp.constraints import ON_DEMAND
from spm_opt.planners.ocp.parameters import nlp_parameters
from spm_opt.planners.ocp.point import ARC_PARAMETERS
from spm_opt.planners.ocp.transcription import STATE, Grid


def plain_nlp(grid: Grid, interval: ca.Function, checks: int, n_dynamics: int) -> dict:
    """The NLP in MX as one graph, for CasADi's AD: x and p laid out as the assembly's."""
    m, segments = grid.intervals, grid.segments
    states, jerks = ca.MX.sym("x", STATE, m + 1), ca.MX.sym("u", 2, m)
    durations = ca.MX.sym("T", 3 * segments)
    arcs = ca.MX.sym("arcs", ARC_PARAMETERS, segments)
    fractions = ca.MX.sym("fractions", checks, m)
    dynamics, weights, scales = ca.MX.sym("d", n_dynamics), ca.MX.sym("w", 3), ca.MX.sym("s", 3)
    h = (ca.DM(grid.interval_matrix) @ durations).T
    interval_arcs = arcs @ ca.DM(np.eye(segments)[:, grid.interval_segments])
    end, rows, integrals = interval.map(m)(
        states[:, :-1], jerks, h, interval_arcs, fractions, dynamics
    )
    g = ca.vertcat(
        ca.vec(ca.vertcat(states[:, 1:] - end, rows)),
        ca.DM(grid.segment_matrix) @ durations,
        ca.sum1(durations),
    )
    f = (
        weights[0] * ca.sum1(durations) / scales[0]
        + weights[1] * ca.sum2(integrals[1, :]) / scales[1]
        + weights[2] * ca.sum2(integrals[0, :]) / scales[2]
    )
    x = ca.vertcat(ca.vec(states), ca.vec(jerks), durations)
    p = ca.vertcat(ca.vec(arcs), ca.vec(fractions), dynamics, weights, scales)
    return {"x": x, "p": p, "f": f, "g": g}


@pytest.mark.parametrize(("with_torque", "demanded"), [(False, frozenset()), (True, ON_DEMAND)])
def test_assembled_derivatives_are_casadis(paper_problem, with_torque, demanded):
    checks, grid = 2, Grid(len(paper_problem.segment_durations), (2, 3, 2))
    joint_range = range_key(paper_problem.robot.joint_range)
    interval = nlp.interval(checks, with_torque, joint_range, demanded)
    n_dynamics = interval.size1_in(5)
    assembled = assemble(grid, interval_functions(interval), ARC_PARAMETERS, checks, n_dynamics)
    plain = plain_nlp(grid, interval, checks, n_dynamics)

    rng = np.random.default_rng(7)
    n, n_g = plain["x"].numel(), plain["g"].numel()
    x = 0.1 * rng.standard_normal(n)
    x[-3 * grid.segments :] = rng.uniform(0.5, 2.0, 3 * grid.segments)
    fractions = rng.uniform(0.1, 0.9, (checks, grid.intervals))
    p = nlp_parameters(paper_problem, fractions, [0.7, 1.3, 0.4], [40.0, 0.6, 0.2], with_torque)
    lam_f, lam_g = 0.8, rng.standard_normal(n_g)

    sigma, lam = ca.MX.sym("sigma"), ca.MX.sym("lam", n_g)
    lagrangian = sigma * plain["f"] + ca.dot(lam, plain["g"])
    reference = ca.Function(
        "reference",
        [plain["x"], plain["p"], sigma, lam],
        [
            plain["f"],
            plain["g"],
            ca.gradient(plain["f"], plain["x"]),
            ca.jacobian(plain["g"], plain["x"]),
            ca.triu(ca.hessian(lagrangian, plain["x"])[0]),
        ],
    )
    f, g, gradient, jacobian, hessian = (v.full() for v in reference(x, p, lam_f, lam_g))
    ours = assembled.derivatives
    f_ours, gradient_ours = (v.full() for v in ours["grad_f"](x, p))
    g_ours, jacobian_ours = (v.full() for v in ours["jac_g"](x, p))
    hessian_ours = ours["hess_lag"](x, p, lam_f, lam_g).full()

    np.testing.assert_allclose(f_ours, f, rtol=1e-12)
    np.testing.assert_allclose(g_ours, g, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(gradient_ours, gradient, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(jacobian_ours, jacobian, rtol=1e-10, atol=1e-10)
    scale = np.max(np.abs(hessian))
    np.testing.assert_allclose(hessian_ours, hessian, rtol=1e-9, atol=1e-12 * scale)
    total, effort, jerk = (float(v) for v in assembled.terms(x, p))
    assert total == pytest.approx(np.sum(x[-3 * grid.segments :]))
    assert (effort > 0) == with_torque and jerk > 0

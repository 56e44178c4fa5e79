"""The trajectory NLP: constraints met (checked with pinocchio), solver built once, free vs arc paths."""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from optlight.errors import SolverError
from optlight.geometry import h_residual
from optlight.pipeline import time_knots, verify_knots
from optlight.plan import joint_path_length
from optlight.planning.path import build_path
from optlight.planning.policy import knot_ik
from optlight.planning.trajectory import TrajectoryNLPResult, TrajectoryOptimizer, knot_cost
from optlight.robot import generalized_ik
from optlight.setup import Setup
from optlight.verify import verify_trajectory


@pytest.fixture(scope="module")
def setup(small_setup: Setup):
    robot, sphere = small_setup.robot, small_setup.sphere
    zen = np.deg2rad([10, 25, 40, 25, 15])
    az = np.deg2rad([0, 60, 120, 200, 300])
    path = build_path(sphere, sphere.position(zen, az), np.arange(5), np.deg2rad(3.0))
    postures = [generalized_ik(robot, sphere, path.positions[0]).theta]
    for k in path.landmark_knots[1:]:
        postures.append(generalized_ik(robot, sphere, path.positions[k], postures[-1], restarts=False).theta)
    warm, failures = knot_ik(small_setup.workcell, path, np.array(postures))
    assert not failures.any()
    return robot, sphere, path, warm


def test_knots_meet_the_light_constraints_and_the_arcs(setup) -> None:
    robot, sphere, path, warm = setup
    opt = TrajectoryOptimizer(robot, max_step=0.25)
    result = opt.solve(path, sphere, warm)
    assert result.success
    theta = result.theta
    positions = []
    for k, q in enumerate(theta):
        assert robot.within_limits(q, tol=1e-7)
        p, r = robot.light_pose(q)  # pinocchio, not the CasADi mirror the NLP used
        assert np.abs(h_residual(p, r, sphere.center, sphere.radius)).max() < 1e-7, k
        positions.append(p)
    positions = np.array(positions)
    np.testing.assert_allclose(positions[path.landmark_knots], path.positions[path.landmark_knots], atol=1e-7)
    for seg in path.segments():  # every knot on its segment's great circle, between its ends
        u0, u1 = path.directions[seg.start], path.directions[seg.stop - 1]
        normal = np.cross(u0, u1) / np.linalg.norm(np.cross(u0, u1))
        d = positions[seg] - sphere.center
        assert np.abs(d @ normal).max() < 1e-7
        assert (d @ np.cross(normal, u0)).min() > -1e-7 and (d @ np.cross(u1, normal)).min() > -1e-7
    assert np.abs(np.diff(theta, axis=0)).max() <= 0.25 + 1e-7
    assert joint_path_length(theta) <= joint_path_length(warm) + 1e-9


def test_free_path_stays_on_the_sphere_and_costs_no_more(setup) -> None:
    robot, sphere, path, warm = setup
    arc = TrajectoryOptimizer(robot, path_mode="arc").solve(path, sphere, warm)
    free = TrajectoryOptimizer(robot, path_mode="free").solve(path, sphere, warm)
    assert arc.success and free.success
    assert free.cost <= arc.cost + 1e-9  # the free path relaxes the arc constraints
    off_arc = 0.0
    for k, q in enumerate(free.theta):
        p, r = robot.light_pose(q)
        assert np.abs(h_residual(p, r, sphere.center, sphere.radius)).max() < 1e-7
        off_arc = max(off_arc, float(np.linalg.norm(p - path.positions[k])))
    assert off_arc > 1e-4, "the free path did leave the planned knots somewhere"


def test_the_solver_is_built_once_per_size(setup, monkeypatch) -> None:
    robot, sphere, path, warm = setup
    built = []
    real = ca.nlpsol
    monkeypatch.setattr(ca, "nlpsol", lambda *a, **k: built.append(a[0]) or real(*a, **k))
    opt = TrajectoryOptimizer(robot)
    for _ in range(3):
        assert opt.solve(path, sphere, warm + 1e-3).success
    assert built == ["trajectory_nlp"]


@pytest.fixture(scope="module")
def transfer(setup, small_setup: Setup):
    """The path with its second segment a transfer (off the sphere), solved from the straight line."""
    robot, sphere, path, _ = setup
    leaving = path.with_transfers([False, True, False, False])
    postures = np.array([generalized_ik(robot, sphere, path.positions[k]).theta for k in path.landmark_knots])
    warm, _ = knot_ik(small_setup.workcell, leaving, postures)
    segment = leaving.segments()[1]
    np.testing.assert_allclose(np.diff(warm[segment], 2, axis=0), 0.0, atol=1e-12)  # the joint-space line
    return leaving, TrajectoryOptimizer(robot, path_mode="free").solve(leaving, sphere, warm)


def test_a_transfer_segment_leaves_the_sphere_outwards_and_the_rest_stays_on_it(setup, transfer) -> None:
    robot, sphere, path, warm = setup
    leaving, result = transfer
    assert result.success
    on_sphere = leaving.on_sphere()
    segment = leaving.segments()[1]
    assert not on_sphere[segment.start + 1 : segment.stop - 1].any() and on_sphere.sum() == (
        path.n_knots - (segment.stop - segment.start - 2)
    )
    h = []
    for q in result.theta:
        p, r = robot.light_pose(q)  # pinocchio, not the CasADi mirror the NLP used
        h.append(np.linalg.norm(h_residual(p, r, sphere.center, sphere.radius)))
    h = np.array(h)
    assert h[on_sphere].max() < 1e-7
    outside = np.linalg.norm(robot.light_positions(result.theta) - sphere.center, axis=1) - sphere.radius
    assert outside[~on_sphere].min() > -1e-7  # never nearer the object than the sphere
    assert h[~on_sphere].max() > 1e-3, "the transfer did leave the sphere (or the aim) somewhere"
    on_the_sphere = TrajectoryOptimizer(robot, path_mode="free").solve(path, sphere, warm)
    assert result.cost <= on_the_sphere.cost + 1e-9  # a transfer relaxes h on its interior knots


def test_verification_skips_the_path_on_transfers_and_checks_the_light_stays_outside(
    small_setup: Setup, setup, transfer
) -> None:
    _, sphere, _, _ = setup
    leaving, result = transfer
    trajectory = time_knots(small_setup, leaving, result.theta)
    captures = leaving.positions[leaving.landmark_knots]
    report = verify_knots(small_setup, trajectory, captures, result.theta, leaving.transfers)
    assert report.checks["outside"].max_value <= 1e-3 and report.checks["path"].passed
    # the same light positions against a sphere 1 cm larger: the transfer is inside it by ~1 cm
    robot, limits = small_setup.robot, small_setup.limits
    deeper = verify_trajectory(
        trajectory,
        light_pose=robot.light_pose,
        lower=limits.lower,
        upper=limits.upper,
        velocity_limit=limits.velocity,
        acceleration_limit=limits.acceleration,
        sphere=replace(sphere, radius=sphere.radius + 0.01),
        landmark_positions=captures,
        transfers=leaving.transfers,
    )
    assert 0.009 < deeper.checks["outside"].max_value and not deeper.checks["outside"].passed


def test_the_pipeline_leaves_the_sphere_only_where_the_nlp_finds_no_way_on_it(
    small_setup: Setup, setup, monkeypatch
) -> None:
    import optlight.planning.trajectory.windows as windows

    _, _, path, warm = setup
    thetas = warm[path.landmark_knots]
    seen, fallbacks = [], []

    def on_the_sphere_fails(cell_, spec_, solver_, path_, warm_, fixed_start, *, fallback=False):
        seen.append(path_.transfers.copy())
        fallbacks.append(fallback)
        if not path_.transfers.any():
            raise SolverError("the trajectory NLP failed (Infeasible_Problem_Detected)")
        return TrajectoryNLPResult(warm_, True, "solved", 0.0, 0.0, 1, 0.0)

    monkeypatch.setattr(windows, "optimize_knots", on_the_sphere_fails)
    monkeypatch.setattr(windows, "NLP_WINDOW_KNOTS", path.n_knots)  # one window: the whole path
    # no knot the per-knot IK missed: the window's last try leaves the sphere on every segment
    left, _, result = windows.optimize_path(
        small_setup.workcell,
        small_setup.trajectory_spec,
        small_setup.solver,
        path,
        warm,
        np.zeros(4, np.int64),
        thetas,
    )
    assert result.status == "solved" and left.transfers.tolist() == [True] * 4
    assert [t.tolist() for t in seen] == [[False] * 4, [True] * 4] and fallbacks == [False, False]
    seen.clear()
    fallbacks.clear()
    left, left_warm, result = windows.optimize_path(
        small_setup.workcell,
        small_setup.trajectory_spec,
        small_setup.solver,
        path,
        warm,
        np.array([0, 0, 3, 0]),
        thetas,
    )
    assert result.status == "solved" and left.transfers.tolist() == [False, False, True, False]
    assert [t.tolist() for t in seen] == [[False] * 4, [False, False, True, False]]
    # the transfers can follow the solve on the sphere only where the IK missed a knot; not themselves
    assert fallbacks == [True, False]
    segment = left.segments()[2]
    np.testing.assert_allclose(np.diff(left_warm[segment], 2, axis=0), 0.0, atol=1e-12)
    np.testing.assert_array_equal(left_warm[: segment.start + 1], warm[: segment.start + 1])
    # no knot missed, but a jump to another IK branch inside segment 0: that segment leaves the sphere
    jumped = warm.copy()
    jumped[path.segments()[0].start + 2] += 1.0
    left, _, _ = windows.optimize_path(
        small_setup.workcell,
        small_setup.trajectory_spec,
        small_setup.solver,
        path,
        jumped,
        np.zeros(4, np.int64),
        thetas,
    )
    assert left.transfers.tolist() == [True, False, False, False]
    # no knot missed, no jump, but the IK's knots collide on segment 3 (by the NLPs' sphere model)
    colliding_knot = warm[path.segments()[3].start + 1]

    class Colliding:
        collisions = True

        def sphere_clearance(self, robot, q):
            return np.array([-0.01 if np.array_equal(q, colliding_knot) else 0.1]), np.zeros(0)

    among_obstacles = replace(small_setup, environment=Colliding())
    left, _, _ = windows.optimize_path(
        among_obstacles.workcell,
        among_obstacles.trajectory_spec,
        among_obstacles.solver,
        path,
        warm,
        np.zeros(4, np.int64),
        thetas,
    )
    assert left.transfers.tolist() == [False, False, False, True]


def test_the_numpy_cost_is_the_nlps(small_setup: Setup, setup) -> None:
    robot, sphere, path, warm = setup
    result = TrajectoryOptimizer(robot, joint_weights=1.0 / small_setup.limits.velocity**2).solve(path, sphere, warm)
    assert result.success
    np.testing.assert_allclose(knot_cost(small_setup.workcell, result.theta), result.cost, rtol=1e-12)
    assert knot_cost(small_setup.workcell, warm) > result.cost


def test_path_windows_cut_at_captures_and_cover_the_path(setup) -> None:
    _, sphere, path, _ = setup
    for size in (1, 10, 30, path.n_knots, 10 * path.n_knots):
        windows = path.windows(size)
        assert windows[0][0] == 0 and windows[-1][1] == len(path.landmark_knots) - 1
        assert all(a[1] == b[0] and a[0] < a[1] for a, b in zip(windows[:-1], windows[1:], strict=True))
        sizes = [path.landmark_knots[last] - path.landmark_knots[first] for first, last in windows]
        assert all(k >= size for k in sizes[:-1]) and (len(sizes) == 1 or sizes[-1] >= size / 2)
    assert path.windows(path.n_knots) == [(0, 4)]
    window = path.window(1, 3)
    knots = slice(path.landmark_knots[1], path.landmark_knots[3] + 1)
    np.testing.assert_array_equal(window.positions, path.positions[knots])
    np.testing.assert_array_equal(window.rotations, path.rotations[knots])
    assert window.landmark_knots.tolist() == (path.landmark_knots[1:4] - knots.start).tolist()
    assert [(s.stop - s.start) for s in window.segments()] == [(s.stop - s.start) for s in path.segments()[1:3]]


def test_a_fixed_start_keeps_its_angles_and_the_rest_finds_the_same_optimum(setup) -> None:
    robot, sphere, path, warm = setup
    opt = TrajectoryOptimizer(robot)
    free = opt.solve(path, sphere, warm)
    start = warm.copy()
    start[0] = free.theta[0]  # the free optimum's first knot, the rest from the IK
    fixed = opt.solve(path, sphere, start, fixed_start=True)
    assert free.success and fixed.success
    np.testing.assert_array_equal(fixed.theta[0], free.theta[0])
    np.testing.assert_allclose(fixed.theta, free.theta, atol=1e-5)
    np.testing.assert_allclose(fixed.cost, free.cost, rtol=1e-6)
    # other ends than the optimum's: kept exactly, the knots next to them follow within a step
    start[0] = generalized_ik(robot, sphere, path.positions[0], free.theta[0] + 0.05, restarts=False).theta
    moved = opt.solve(path, sphere, start, fixed_start=True)
    assert moved.success and np.array_equal(moved.theta[0], start[0]) and moved.cost > free.cost
    assert np.abs(moved.theta[1] - start[0]).max() <= 0.25 + 1e-7


def test_a_window_that_fails_is_solved_with_the_one_before_then_named(
    small_setup: Setup, setup, monkeypatch
) -> None:
    import optlight.planning.trajectory.windows as windows

    _, _, path, warm = setup
    calls = []

    def fails_from_a_fixed_start(cell_, spec_, solver_, path_, warm_, fixed_start, *, fallback=False):
        calls.append((path_.n_knots, fixed_start))
        if fixed_start:
            raise SolverError("the trajectory NLP failed (Infeasible_Problem_Detected)")
        return TrajectoryNLPResult(warm_, True, "solved", 1.0, 0.0, 1, 0.0)

    monkeypatch.setattr(windows, "optimize_knots", fails_from_a_fixed_start)
    monkeypatch.setattr(windows, "NLP_WINDOW_KNOTS", 15)
    assert path.windows(15) == [(0, 2), (2, 3), (3, 4)] and path.landmark_knots.tolist() == [0, 8, 20, 35, 46]
    # the second window fails from the first's end, and is solved with the first (free start); the
    # third fails from the second's end, with the second (fixed start at the first's end), and with
    # every segment a transfer (from the second's end)
    with pytest.raises(SolverError, match=r"between captures 3 and 4 \(visiting order\): the trajectory NLP"):
        windows.optimize_path(
            small_setup.workcell,
            small_setup.trajectory_spec,
            small_setup.solver,
            path,
            warm,
            np.zeros(4, np.int64),
            warm[path.landmark_knots],
        )
    assert calls == [(21, False), (16, True), (36, False), (12, True), (27, True), (12, True)]


def test_a_failed_solve_is_tried_again_from_a_small_barrier(small_setup: Setup, setup, monkeypatch) -> None:
    from optlight.planning import trajectory

    _, _, path, warm = setup
    real = trajectory.TrajectoryOptimizer.solve
    barriers, expects, budgets = [], [], []

    def fails_from_the_default_barrier(self, path_, sphere, theta0, fixed_start=False, fixed_end=False):
        barriers.append(self.options.get("ipopt.mu_init"))
        expects.append(self.options.get("ipopt.expect_infeasible_problem"))
        budgets.append(self.options["ipopt.max_iter"])
        result = real(self, path_, sphere, theta0, fixed_start, fixed_end)
        return result if barriers[-1] is not None else replace(result, success=False, status="Infeasible_Problem_Detected")

    monkeypatch.setattr(trajectory.TrajectoryOptimizer, "solve", fails_from_the_default_barrier)
    free = replace(small_setup, environment=None)  # the fixture's path ignores the view: no environment
    result = trajectory.optimize_knots(free.workcell, free.trajectory_spec, free.solver, path, warm)
    assert barriers == [None, trajectory.WARM_MU_INIT] and result.success
    assert expects == [None, "yes"]  # the retry, not the first try, expects an infeasible problem
    assert budgets == [trajectory.FIRST_TRY_ITER, free.solver.max_iter] and trajectory.FIRST_TRY_ITER < free.solver.max_iter
    alone = real(trajectory.TrajectoryOptimizer(free.robot, joint_weights=1.0 / free.limits.velocity**2, retry=True), path, free.sphere, warm)
    assert result.iterations > alone.iterations  # both tries counted


def _failing_tries(monkeypatch) -> tuple[list, list]:
    """Make every trajectory NLP solve end infeasible (after really running it); the lists its
    tries' initial barriers (None: IPOPT's default) and iteration budgets are recorded in."""
    from optlight.planning import trajectory

    real = trajectory.TrajectoryOptimizer.solve
    barriers: list = []
    budgets: list = []

    def fails(self, path_, sphere, theta0, fixed_start=False, fixed_end=False):
        barriers.append(self.options.get("ipopt.mu_init"))
        budgets.append(self.options["ipopt.max_iter"])
        return replace(real(self, path_, sphere, theta0, fixed_start, fixed_end), success=False, status="Infeasible_Problem_Detected")

    monkeypatch.setattr(trajectory.TrajectoryOptimizer, "solve", fails)
    return barriers, budgets


def test_no_small_barrier_retry_from_a_warm_start_off_the_sphere(small_setup: Setup, setup, monkeypatch) -> None:
    """A knot the per-knot IK missed leaves the warm start centimetres off the sphere: the small
    barrier has no feasible point to stay near, so a failed solve is not tried again."""
    from optlight.planning import trajectory
    from optlight.planning.trajectory import knots

    _, _, path, warm = setup
    barriers, budgets = _failing_tries(monkeypatch)
    free = replace(small_setup, environment=None)
    assert knots._warm_start_on_sphere(free, path, warm)
    missed = warm.copy()
    missed[3] += 0.05  # one knot: the light ~2 cm off the sphere
    assert not knots._warm_start_on_sphere(free, path, missed)
    with pytest.raises(SolverError, match="Infeasible_Problem_Detected"):
        trajectory.optimize_knots(free.workcell, free.trajectory_spec, free.solver, path, missed)
    assert barriers == [None]
    assert budgets == [free.solver.max_iter]  # the only try: all of [solver] max_iter


def test_with_a_fallback_to_follow_the_first_try_has_its_budget_and_no_retry(
    small_setup: Setup, setup, monkeypatch
) -> None:
    """Where the caller's transfers can follow (a warm start with a segment the IK did not follow),
    a failed first try is not tried again from the small barrier, and stops at FIRST_TRY_ITER even
    from a warm start off the sphere; without the fallback that warm start's try has all of max_iter."""
    from optlight.planning import trajectory

    _, _, path, warm = setup
    barriers, budgets = _failing_tries(monkeypatch)
    free = replace(small_setup, environment=None)
    missed = warm.copy()
    missed[3] += 0.05  # off the sphere: no retry either way
    for start, fallback, budget in ((warm, True, trajectory.FIRST_TRY_ITER), (missed, True, trajectory.FIRST_TRY_ITER), (missed, False, free.solver.max_iter)):
        barriers.clear()
        budgets.clear()
        with pytest.raises(SolverError, match="Infeasible_Problem_Detected"):
            trajectory.optimize_knots(
                free.workcell, free.trajectory_spec, free.solver, path, start, fallback=fallback
            )
        assert barriers == [None] and budgets == [budget]


def test_the_first_try_stops_at_its_budget_and_the_retry_solves(small_setup: Setup, setup, monkeypatch) -> None:
    """With a retry to follow, IPOPT itself stops the first try after FIRST_TRY_ITER iterations (3
    here, where it needs more), and the retry from the small barrier solves the NLP."""
    from optlight.planning import trajectory
    from optlight.planning.trajectory import knots

    _, _, path, warm = setup
    real = trajectory.TrajectoryOptimizer.solve
    tries = []

    def recorded(self, path_, sphere, theta0, fixed_start=False, fixed_end=False):
        tries.append(real(self, path_, sphere, theta0, fixed_start, fixed_end))
        return tries[-1]

    monkeypatch.setattr(trajectory.TrajectoryOptimizer, "solve", recorded)
    monkeypatch.setattr(knots, "FIRST_TRY_ITER", 3)
    free = replace(small_setup, environment=None)
    result = trajectory.optimize_knots(free.workcell, free.trajectory_spec, free.solver, path, warm)
    assert [(t.status, t.iterations) for t in tries[:1]] == [("Maximum_Iterations_Exceeded", 3)]
    assert len(tries) == 2 and tries[1].success and result.success and tries[1].iterations > 3


def test_the_nlps_hessian_and_jacobian_are_casadis_own(monkeypatch) -> None:
    """Our Hessian of the Lagrangian and Jacobian of the constraints (knot by knot,
    :func:`optlight.planning.nlp.knot_derivatives`) against those CasADi derives from the whole NLP,
    at random points and multipliers: the trajectory NLP with clearance and view rows (arc rows, a
    fixed start, a knot off the sphere), the transfer NLP and the clear-posture NLP of a row set,
    each with every row at every knot and with some (knot, row) pairs only. The Jacobian has
    CasADi's sparsity, so IPOPT's linear algebra is the same."""
    from conftest import reduced_problem

    from optlight.planning.nlp import environment_rows
    from optlight.planning.placement import ClearPosture
    from optlight.planning.trajectory import transfer

    setup = Setup.from_problem(reduced_problem("table_wall"))
    env, robot = setup.environment, setup.robot
    captured: list[tuple[dict, dict]] = []
    real = ca.nlpsol

    def capture(name: str, plugin: str, nlp: dict, options: dict) -> ca.Function:
        captured.append((nlp, options))
        return real(name, plugin, nlp, options)

    monkeypatch.setattr(ca, "nlpsol", capture)
    values = env.clearance_values(robot, robot.theta_ref[None])[0]
    near = np.flatnonzero(values < 0.3)
    clearance = env.clearance_function(robot, near)
    # every near row at every knot, then (knot, row) pairs only: the rest keep no multiplier
    active = np.random.default_rng(3).random((12, len(near))) < 0.5
    for mask in (None, active):
        optimizer = TrajectoryOptimizer(
            robot, path_mode="arc", clearance=clearance, active=mask, view=env.view_cone_function(robot)
        )
        optimizer._solver(12, (0, 5, 11), (6, 7), False)
        optimizer._solver(12, (0, 5, 11), (0, 1), True)
    q = ca.MX.sym("q", robot.n)
    rows = ca.Function("rows", [q], [environment_rows(env, robot, q)])
    ends, initial = (robot.theta_ref, robot.theta_ref + 0.3), robot.theta_ref + np.zeros((4, 1))
    transfer._transfer_nlp(setup.workcell, setup.solver, rows, *ends, initial)
    transfer._transfer_nlp(
        setup.workcell, setup.solver, rows, *ends, initial, np.random.default_rng(5).random((4, rows.size1_out(0))) < 0.5
    )
    posture = ClearPosture(setup.workcell, env, setup.solver)
    monkeypatch.setattr(ca, "nlpsol", capture)
    posture._solver(np.random.default_rng(6).random((1, env.clearance_function(robot).size1_out(0))) < 0.2, False)
    assert len(captured) == 7
    rng = np.random.default_rng(4)
    for nlp, options in captured:
        reference = real("reference", "ipopt", nlp, {"ipopt.print_level": 0, "print_time": False})
        assert nlp["g"].size1() > 50  # the environment's rows are in it
        for _ in range(3):
            args = [
                robot.theta_ref.tolist() * (nlp["x"].size1() // robot.n) + rng.normal(scale=0.3, size=nlp["x"].size1()),
                rng.normal(size=nlp["p"].size1()),
                rng.uniform(0.1, 2.0),
                rng.normal(size=nlp["g"].size1()),
            ]
            ours = options["hess_lag"](*args).full()
            theirs = reference.get_function("nlp_hess_l")(*args).full()
            np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-12 * np.abs(theirs).max())
            (g, jacobian), (g_ref, jacobian_ref) = (f(*args[:2]) for f in (options["jac_g"], reference.get_function("nlp_jac_g")))
            np.testing.assert_array_equal(g.full(), g_ref.full())
            assert jacobian.sparsity() == jacobian_ref.sparsity() and jacobian.nnz() > 0
            ours, theirs = (np.asarray(j.nonzeros()) for j in (jacobian, jacobian_ref))
            np.testing.assert_allclose(ours, theirs, rtol=1e-14, atol=1e-14 * np.abs(theirs).max())


def test_knot_maps_on_threads_give_the_serial_maps_values(small_setup: Setup, monkeypatch) -> None:
    """:func:`~optlight.planning.nlp.knot_map` splits the knots over the threads (CasADi's ThreadMap)
    from THREADED_KNOTS knots on, and not with one thread: the knot rows, their Jacobian and their
    Hessian are those of the serial map, to the bit."""
    from optlight.planning.nlp import THREADED_KNOTS, knot_map, row_hessian

    robot = small_setup.robot
    rows = small_setup.environment.view_cone_function(robot)
    hessian = row_hessian(rows)
    count = THREADED_KNOTS + 3
    rng = np.random.default_rng(9)
    theta = robot.theta_ref[:, None] + rng.normal(scale=0.4, size=(robot.n, count))
    lam = rng.uniform(0.0, 1.0, size=(rows.size1_out(0), count))
    x = ca.MX.sym("x", robot.n, count)

    def values(threads: str) -> list[np.ndarray]:
        monkeypatch.setenv("OMP_NUM_THREADS", threads)
        mapped, hessians = knot_map(rows, count), knot_map(hessian, count)
        # on threads: a ThreadMap, or one in an MXFunction with a serial map of the knots left over
        kinds = {"ThreadMap", "MXFunction"} if threads == "2" else {"Map"}
        assert {mapped.class_name(), hessians.class_name()} <= kinds
        assert knot_map(rows, THREADED_KNOTS - 1).class_name() == "Map"
        jacobian = ca.Function("rows_jacobian", [x], [ca.jacobian(ca.vec(mapped(x)), ca.vec(x))])
        return [np.asarray(f) for f in (mapped(theta), jacobian(theta).full(), hessians(theta, lam))]

    serial, threaded = values("1"), values("2")
    assert np.abs(serial[1]).max() > 0.1  # the rows depend on the angles
    for a, b in zip(serial, threaded, strict=True):
        np.testing.assert_array_equal(a, b)

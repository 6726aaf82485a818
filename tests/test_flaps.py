"""Random bone flaps: seeded, of the asked size, reachable, convex, ready for problem files."""

import math
import tomllib

import numpy as np
import pytest
from conftest import ROOT

import spm_opt as so
from spm_opt.model.params import MM
from spm_opt.studies.sweep.flaps import DURATION_SPEED_FRACTION, Flap, random_flaps

SIZES_MM = (20.0, 90.0)
SPEED_MM_S = 3.0
TOLERANCES_MM = (0.05, 0.2)
SPEED_LIMITS_MM_S = (2.0, 4.0)


@pytest.fixture(scope="module")
def flaps(paper_problem: so.Problem) -> list[Flap]:
    return [
        *random_flaps(paper_problem, 8, SIZES_MM, seed=11),
        *random_flaps(paper_problem, 4, SIZES_MM, landmarks=3, seed=12),
        *random_flaps(paper_problem, 4, SIZES_MM, landmarks=6, seed=13),
    ]


@pytest.fixture(scope="module")
def varied(paper_problem: so.Problem) -> list[Flap]:
    """200 flaps of 4-6 landmarks, each with its own contour tolerance and speed limit."""
    return random_flaps(
        paper_problem,
        200,
        (20.0, 50.0),
        (4, 6),
        seed=21,
        contour_tolerance_mm=TOLERANCES_MM,
        max_tool_speed_mm_s=SPEED_LIMITS_MM_S,
    )


def _tangent_plane(flap: Flap) -> np.ndarray:
    """Gnomonic projection (n, 2) at the landmarks' mean direction, in a frame right-handed
    about the outward normal (great-circle arcs project to straight segments)."""
    directions = flap.positions_mm / np.linalg.norm(flap.positions_mm, axis=1, keepdims=True)
    centre = directions.mean(axis=0)
    centre /= np.linalg.norm(centre)
    first = np.cross([0.0, 1.0, 0.0], centre)
    first /= np.linalg.norm(first)
    second = np.cross(centre, first)
    depth = directions @ centre
    return np.column_stack([directions @ first, directions @ second]) / depth[:, None]


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _segments_cross(p: np.ndarray, q: np.ndarray, r: np.ndarray, s: np.ndarray) -> bool:
    """Whether segments pq and rs intersect (touching included)."""
    d1, d2 = _cross(q - p, r - p), _cross(q - p, s - p)
    d3, d4 = _cross(s - r, p - r), _cross(s - r, q - r)
    return d1 * d2 <= 0.0 and d3 * d4 <= 0.0


def test_same_seed_same_flaps_other_seed_other_flaps(paper_problem):
    first = random_flaps(paper_problem, 3, SIZES_MM, seed=5)
    again = random_flaps(paper_problem, 3, SIZES_MM, seed=5)
    other = random_flaps(paper_problem, 3, SIZES_MM, seed=6)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a.positions_mm, b.positions_mm)
        assert (a.names, a.size_mm) == (b.names, b.size_mm)
    for a, c in zip(first, other, strict=True):
        assert not np.array_equal(a.positions_mm, c.positions_mm)


def test_sizes_are_in_range_and_match_the_landmarks(flaps):
    for flap in flaps:
        assert SIZES_MM[0] <= flap.size_mm <= SIZES_MM[1]
        gaps = flap.positions_mm[:, None, :] - flap.positions_mm[None, :, :]
        assert np.max(np.linalg.norm(gaps, axis=-1)) == pytest.approx(flap.size_mm, abs=0.02)
        assert flap.names == tuple(f"F{i + 1}" for i in range(len(flap.positions_mm)))
    sizes = [flap.size_mm for flap in flaps]
    assert max(sizes) - min(sizes) > 0.3 * (SIZES_MM[1] - SIZES_MM[0])  # spread, not stuck


def test_every_flap_is_a_valid_problem_for_the_base_robot(paper_problem, flaps):
    radii = np.linalg.norm(paper_problem.landmarks, axis=1) / MM
    for flap in flaps:
        problem = flap.problem(paper_problem, SPEED_MM_S)  # validates: raises if unreachable
        assert problem.closed and problem.robot is paper_problem.robot
        q = paper_problem.robot.check_reachable(problem.platform_points, list(flap.names))
        assert np.all(np.abs(q) <= paper_problem.robot.joint_range[:, 1] + 1e-12)
        skull = np.linalg.norm(flap.positions_mm, axis=1)
        assert np.all((skull > radii.min() - 0.01) & (skull < radii.max() + 0.01))
        assert np.ptp(skull) < 0.02  # one sphere, up to the rounding of positions


def test_flaps_are_convex_loops_in_visiting_order(flaps):
    for flap in flaps:
        plane = _tangent_plane(flap)
        n = len(plane)
        edges = np.roll(plane, -1, axis=0) - plane
        turns = [_cross(edges[i], edges[(i + 1) % n]) for i in range(n)]
        assert all(turn > 0.0 for turn in turns)  # counterclockwise seen from outside
        exterior = sum(
            math.atan2(_cross(edges[i], edges[(i + 1) % n]), edges[i] @ edges[(i + 1) % n])
            for i in range(n)
        )
        assert exterior == pytest.approx(2 * math.pi)  # one turn: no self-intersection
        for i in range(n):
            for j in range(i + 2, n):
                if (j + 1) % n == i:
                    continue  # adjacent through the closing segment
                a, b = plane[i], plane[(i + 1) % n]
                assert not _segments_cross(a, b, plane[j], plane[(j + 1) % n])


def test_overrides_are_problem_file_landmark_tables(paper_problem, flaps, tmp_path):
    shipped = tomllib.loads((ROOT / "problems" / "craniotomy_bone_flap.toml").read_text())
    shipped_keys = {tuple(sorted(table)) for table in shipped["landmarks"]}
    flap = flaps[0]
    overrides = flap.landmark_overrides()
    assert {tuple(sorted(table)) for table in overrides} == shipped_keys
    for table, name, position in zip(overrides, flap.names, flap.positions_mm, strict=True):
        assert table["name"] == name
        assert len(table["position_mm"]) == 3
        assert all(type(v) is float and v == round(v, 2) for v in table["position_mm"])
        assert table["position_mm"] == position.tolist()
    durations = flap.segment_durations_s(SPEED_MM_S)
    assert all(type(d) is float for d in durations)
    landmark_tables = "".join(
        f'\n[[landmarks]]\nname = "{t["name"]}"\nposition_mm = {t["position_mm"]!r}\n'
        for t in overrides
    )
    text = (
        f'name = "flap"\nrobot = "{ROOT / "problems" / "robots" / "prototype.toml"}"\n'
        f"closed = true\nsegment_durations_s = {durations!r}\n"
        f"[limits]\nmax_joint_speed_rpm = 13.7\n{landmark_tables}"
    )
    (tmp_path / "flap.toml").write_text(text)
    loaded = so.load_problem(tmp_path / "flap.toml")
    np.testing.assert_array_equal(loaded.landmarks, flap.positions_mm * MM)
    assert loaded.landmark_names == flap.names
    np.testing.assert_array_equal(loaded.segment_durations, durations)


def test_segment_durations_follow_the_arc_lengths(flaps):
    for flap in flaps:
        points = flap.positions_mm
        following = np.roll(points, -1, axis=0)
        unit = points / np.linalg.norm(points, axis=1, keepdims=True)
        angles = np.arctan2(
            np.linalg.norm(np.cross(unit, np.roll(unit, -1, axis=0)), axis=1),
            np.einsum("ij,ij->i", unit, np.roll(unit, -1, axis=0)),
        )
        radii = (np.linalg.norm(points, axis=1) + np.linalg.norm(following, axis=1)) / 2
        lengths = radii * angles  # great-circle arcs on the (nearly) spherical skull, mm
        for speed in (0.5, SPEED_MM_S):
            durations = np.array(flap.segment_durations_s(speed))
            assert np.all(durations >= 1.0)
            np.testing.assert_allclose(durations * 10, np.round(durations * 10), atol=1e-9)
            floor = np.maximum(1.0, lengths / speed)
            assert np.all(durations >= floor - 1e-3)
            assert np.all(durations < floor + 0.1 + 1e-3)


def test_tiny_flaps_take_at_least_a_second_per_segment(paper_problem):
    (flap,) = random_flaps(paper_problem, 1, (2.0, 2.0), seed=3)
    assert flap.segment_durations_s(SPEED_MM_S) == [1.0] * 4


def test_cubic_planner_succeeds_on_generated_flaps(paper_problem, flaps):
    for flap in flaps[:2] + flaps[-1:]:
        problem = flap.problem(paper_problem, SPEED_MM_S)
        trajectory = so.plan(problem, "cubic")
        assert trajectory.duration == pytest.approx(problem.segment_durations.sum())
        np.testing.assert_allclose(
            trajectory.position(problem.waypoint_times), problem.waypoint_angles, atol=1e-9
        )


def test_new_draws_leave_the_shapes_alone(paper_problem):
    """Drawing limits, or a landmark range of one count, draws the same flaps as without."""
    plain = random_flaps(paper_problem, 6, (20.0, 50.0), 4, seed=2026)
    limited = random_flaps(
        paper_problem,
        6,
        (20.0, 50.0),
        (4, 4),
        seed=2026,
        contour_tolerance_mm=TOLERANCES_MM,
        max_tool_speed_mm_s=SPEED_LIMITS_MM_S,
    )
    for a, b in zip(plain, limited, strict=True):
        np.testing.assert_array_equal(a.positions_mm, b.positions_mm)
        assert (a.names, a.size_mm) == (b.names, b.size_mm)
        assert (a.contour_tolerance_mm, a.max_tool_speed_mm_s) == (None, None)
        assert a.limit_overrides() == {} and a.mean_speed_mm_s(2.0) == 2.0
    # and the tolerances do not depend on whether the speed limit is drawn too
    alone = random_flaps(paper_problem, 6, (20.0, 50.0), seed=2026, contour_tolerance_mm=(0.1, 0.2))
    both = random_flaps(
        paper_problem,
        6,
        (20.0, 50.0),
        seed=2026,
        contour_tolerance_mm=(0.1, 0.2),
        max_tool_speed_mm_s=SPEED_LIMITS_MM_S,
    )
    assert [f.contour_tolerance_mm for f in alone] == [f.contour_tolerance_mm for f in both]


def test_landmark_counts_are_drawn_in_the_range(varied):
    counts = [len(flap.names) for flap in varied]
    assert set(counts) == {4, 5, 6}
    assert all(flap.names == tuple(f"F{i + 1}" for i in range(len(flap.names))) for flap in varied)


def test_limits_are_drawn_in_their_ranges_the_tolerance_log_uniformly(paper_problem, varied):
    tolerances = np.array([flap.contour_tolerance_mm for flap in varied])
    speeds = np.array([flap.max_tool_speed_mm_s for flap in varied])
    assert np.all((tolerances >= 0.05) & (tolerances <= 0.2))
    assert np.all((speeds >= 2.0) & (speeds <= 4.0))
    # log-uniform: half below the geometric mean, 0.1 mm (uniform would put a third there)
    assert 0.4 < np.mean(tolerances < 0.1) < 0.6
    assert 0.4 < np.mean(speeds < 3.0) < 0.6  # uniform: half below the middle
    again = random_flaps(
        paper_problem,
        3,
        (20.0, 50.0),
        (4, 6),
        seed=21,
        contour_tolerance_mm=TOLERANCES_MM,
        max_tool_speed_mm_s=SPEED_LIMITS_MM_S,
    )
    assert [f.limit_overrides() for f in again] == [f.limit_overrides() for f in varied[:3]]


def test_equal_bounds_draw_that_value(paper_problem):
    (flap,) = random_flaps(
        paper_problem, 1, (30.0, 30.0), contour_tolerance_mm=(0.1, 0.1), max_tool_speed_mm_s=(3, 3)
    )
    assert flap.limit_overrides() == {
        "limits.contour_tolerance_mm": 0.1,
        "limits.max_tool_speed_mm_s": 3.0,
    }


def test_drawn_limits_set_the_problem_and_slow_its_durations(paper_problem, varied):
    for flap in varied[:20]:
        problem = flap.problem(paper_problem, 2.0)
        assert problem.limits.contour_tolerance == pytest.approx(flap.contour_tolerance_mm * MM)
        assert problem.limits.max_tool_speed == pytest.approx(flap.max_tool_speed_mm_s * MM)
        assert problem.limits.max_joint_speed == paper_problem.limits.max_joint_speed
        mean = flap.mean_speed_mm_s(2.0)
        assert mean == min(2.0, DURATION_SPEED_FRACTION * flap.max_tool_speed_mm_s)
        np.testing.assert_array_equal(problem.segment_durations, flap.segment_durations_s(mean))
    slow = [flap for flap in varied if flap.max_tool_speed_mm_s < 3.0]
    assert slow and all(flap.mean_speed_mm_s(2.0) < 2.0 for flap in slow)


@pytest.mark.parametrize(
    ("arguments", "named"),
    [
        ({"count": 0}, "count"),
        ({"count": 2.0}, "count"),
        ({"count": True}, "count"),
        ({"landmarks": 2}, "landmarks"),
        ({"landmarks": 4.0}, "landmarks"),
        ({"seed": -1}, "seed"),
        ({"size_range_mm": (30.0, 20.0)}, "size_range_mm"),
        ({"size_range_mm": (-5.0, 20.0)}, "size_range_mm"),
        ({"size_range_mm": (0.0, 20.0)}, "size_range_mm"),
        ({"size_range_mm": (math.nan, 20.0)}, "size_range_mm"),
        ({"size_range_mm": (10.0, math.inf)}, "size_range_mm"),
        ({"size_range_mm": (10.0,)}, "size_range_mm"),
        ({"size_range_mm": ("10", "20")}, "size_range_mm"),
        ({"size_range_mm": 30.0}, "size_range_mm"),
        ({"landmarks": (2, 5)}, "landmarks"),
        ({"landmarks": (5, 4)}, "landmarks"),
        ({"landmarks": (4.0, 5)}, "landmarks"),
        ({"landmarks": (4,)}, "landmarks"),
        ({"landmarks": (4, 5, 6)}, "landmarks"),
        ({"landmarks": "4"}, "landmarks"),
        ({"contour_tolerance_mm": (0.0, 0.2)}, "contour_tolerance_mm"),
        ({"contour_tolerance_mm": (-0.1, 0.2)}, "contour_tolerance_mm"),
        ({"contour_tolerance_mm": (0.2, 0.1)}, "contour_tolerance_mm"),
        ({"contour_tolerance_mm": (0.1, math.inf)}, "contour_tolerance_mm"),
        ({"contour_tolerance_mm": 0.1}, "contour_tolerance_mm"),
        ({"max_tool_speed_mm_s": (0.0, 3.0)}, "max_tool_speed_mm_s"),
        ({"max_tool_speed_mm_s": (4.0, 2.0)}, "max_tool_speed_mm_s"),
        ({"max_tool_speed_mm_s": (math.nan, 3.0)}, "max_tool_speed_mm_s"),
        ({"max_tool_speed_mm_s": (True, 3.0)}, "max_tool_speed_mm_s"),
    ],
)
def test_bad_arguments_give_one_line_errors(paper_problem, arguments, named):
    call = {"count": 1, "size_range_mm": SIZES_MM, **arguments}
    with pytest.raises(so.InputError) as error:
        random_flaps(paper_problem, **call)
    message = str(error.value)
    assert "\n" not in message and message.startswith(f"{named} = ") and "expected" in message


@pytest.mark.parametrize("speed", [0.0, -1.0, math.nan, math.inf, "3", True])
def test_bad_speed_gives_a_one_line_error(flaps, speed):
    with pytest.raises(so.InputError, match=r"^speed_mm_s = .*expected") as error:
        flaps[0].segment_durations_s(speed)
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("sizes", [(140.0, 150.0), (300.0, 500.0)])
def test_flaps_bigger_than_the_workspace_give_a_clear_error(paper_problem, sizes):
    with pytest.raises(so.InputError, match=r"^size_range_mm = .*fits the workspace") as error:
        random_flaps(paper_problem, 2, sizes)
    assert "\n" not in str(error.value)
    assert not isinstance(error.value, so.UnreachableError)

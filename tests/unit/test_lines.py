"""Line extraction from a 2D scan: hand-built scans of a box room with the things a real scan
carries (range noise, dust, a missing beam, the robot's frame posts, a round rock)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ramp.autonomy.perception.lines import extract_lines, fit_line

STEP = math.radians(0.25)
ANGLES = (np.arange(1081) - 540) * STEP


def room_ranges(x: float, y: float, length: float = 6.0, width: float = 4.0) -> np.ndarray:
    """Exact ranges from (x, y) facing +x to the walls of a length x width room."""
    c, s = np.cos(ANGLES), np.sin(ANGLES)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (length - x) / c, np.where(c < 0, -x / c, np.inf))
        ty = np.where(s > 0, (width - y) / s, np.where(s < 0, -y / s, np.inf))
    return np.minimum(tx, ty)


def points(ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ok = np.isfinite(ranges)
    r, a = ranges[ok], ANGLES[ok]
    return np.column_stack((r * np.cos(a), r * np.sin(a))), np.nonzero(ok)[0]


def wall_lines(segments: list) -> dict[str, object]:  # noqa: ANN001
    """The segments keyed by the wall their normal points at (sensor at the origin)."""
    out = {}
    for seg in segments:
        ang = math.degrees(seg.normal_angle)
        for name, want in (("front", 0.0), ("left", 90.0), ("back", 180.0), ("right", -90.0)):
            if abs(math.remainder(ang - want, 360.0)) < 3.0:
                out[name] = seg
    return out


def test_fit_line_gives_the_normal_away_from_the_sensor_and_its_distance() -> None:
    pts = np.array([[2.0, -1.0], [2.0, 0.0], [2.0, 1.5]])
    normal, rho, rms = fit_line(pts)
    assert normal == pytest.approx((1.0, 0.0), abs=1e-12)
    assert rho == pytest.approx(2.0) and rms == pytest.approx(0.0, abs=1e-12)
    normal, rho, _ = fit_line(pts, origin=(3.0, 0.0))  # seen from the other side
    assert normal == pytest.approx((-1.0, 0.0), abs=1e-12) and rho == pytest.approx(1.0)


def test_a_box_room_gives_each_wall_in_view_with_its_corners() -> None:
    # From (2, 1.5) facing +x the 270-degree scan sees the front, left and right walls, and
    # a piece of the back wall past the left one (its right part hides behind the right wall).
    pts, beams = points(room_ranges(2.0, 1.5))
    segs = extract_lines(pts, beams)
    walls = wall_lines(segs)
    assert set(walls) == {"front", "left", "right", "back"}
    assert len(segs) == 4
    assert walls["back"].rho == pytest.approx(2.0, abs=1e-6)
    assert walls["back"].start == pytest.approx((-2.0, 2.5), abs=0.02)
    assert walls["front"].rho == pytest.approx(4.0, abs=1e-6)
    assert walls["left"].rho == pytest.approx(2.5, abs=1e-6)
    assert walls["right"].rho == pytest.approx(1.5, abs=1e-3)
    # The front wall runs from corner to corner, swept right to left (counter-clockwise).
    front = walls["front"]
    assert front.start == pytest.approx((4.0, -1.5), abs=0.03)  # one beam apart at most
    assert front.end == pytest.approx((4.0, 2.5), abs=0.03)
    assert front.count > 200 and front.rms < 1e-9


def test_noise_dust_and_a_missing_beam_do_not_break_a_wall() -> None:
    rng = np.random.default_rng(4)
    ranges = room_ranges(2.0, 1.5) + rng.normal(0.0, 0.01, 1081)
    dust = rng.choice(1081, 12, replace=False)
    ranges[dust] = rng.uniform(0.2, 1.2, 12)  # puffs of regolith in front of the walls
    ranges[540] = np.nan  # one beam with no echo, straight ahead
    pts, beams = points(ranges)
    walls = wall_lines(extract_lines(pts, beams))
    assert set(walls) == {"front", "left", "right", "back"}
    assert walls["front"].rho == pytest.approx(4.0, abs=0.01)
    assert walls["front"].rms < 0.015
    assert walls["front"].length > 3.8  # merged across the gaps, corner to corner


def test_the_robots_own_posts_and_a_rock_are_not_walls() -> None:
    ranges = room_ranges(2.0, 1.5)
    # The BLE's two frame posts at ~0.4 m, seen at +-125..135 deg (thesis fig. 5.38).
    for centre in (130.0, -130.0):
        lo, hi = 540 + int((centre - 4) * 4), 540 + int((centre + 4) * 4)
        ranges[lo:hi] = 0.4
    # A 0.3 m round rock 1.5 m ahead: an arc, not a straight surface.
    cx, r = 1.5, 0.15
    c = np.cos(ANGLES)
    disc = cx * c
    under = disc ** 2 - (cx ** 2 - r ** 2)
    hit = (under > 0) & (c > 0)
    ranges[hit] = np.minimum(ranges[hit], disc[hit] - np.sqrt(under[hit]))
    pts, beams = points(ranges)
    segs = extract_lines(pts, beams)
    assert all(seg.rho > 1.0 for seg in segs)  # nothing near the sensor
    assert set(wall_lines(segs)) == {"front", "left", "right"}  # the posts hide the back
    assert len(segs) == 3  # and nothing else: posts and rock dropped


def test_too_few_points_give_no_segments() -> None:
    assert extract_lines(np.zeros((3, 2))) == []
    assert extract_lines(np.zeros((0, 2))) == []

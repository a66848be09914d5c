"""The autonomy's map of the RMC arena (SPEC 6.1): what a team knows before the run.

Frame: x along the arena's length, 0 at the wall the collector stands behind, 7.38 m at the
far wall; y across, 0..3.88 m, +y on the left when facing +x; z up; yaw counter-clockwise
from +x, in radians in code. A robot pose is the centre of its footprint and its heading.

The obstacles are not here: the autonomy finds them with its own sensors. The simulator keeps
its own copy of these numbers (`firmware_like/`), and a test checks that both agree.
"""

from __future__ import annotations

ARENA_LENGTH_M = 7.38
ARENA_WIDTH_M = 3.88
WALL_HEIGHT_M = 1.0  # at least (SPEC 6.1)

START_END_X_M = 1.5  # start region: 0 <= x < 1.5
START_SPLIT_Y_M = 1.94  # right box y < 1.94, left box y >= 1.94
OBSTACLE_END_X_M = 4.44  # obstacle region: 1.5 <= x < 4.44; digging 4.44 <= x <= 7.38

COLLECTOR_Y_M = 1.94  # centre of the collector bin, behind the x = 0 wall
COLLECTOR_WIDTH_M = 1.65

ROBOT_LENGTH_M = 1.2  # MARTE's footprint
ROBOT_WIDTH_M = 0.75

START_BOXES = ("left", "right")
HEADINGS_DEG = (0, 90, 180, 270)

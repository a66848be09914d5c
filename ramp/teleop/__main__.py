"""`python -m ramp.teleop`: the same as `ramp-teleop`."""

import sys

from ramp.teleop.cli import main

sys.exit(main())

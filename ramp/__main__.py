"""`python -m ramp ...` is `ramp ...`."""

import sys

from ramp.cli import main

sys.exit(main())

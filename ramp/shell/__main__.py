"""`python -m ramp.shell`: the same as `ramp-shell`."""

import sys

from ramp.shell.cli import main

sys.exit(main())

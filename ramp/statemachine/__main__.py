"""`python -m ramp.statemachine --mermaid | --states`: the mission drawn from its own machine.

`--mermaid` prints the state diagram (mermaid `stateDiagram-v2`) and `--states` the table of
states, exactly as the docs page docs/autonomy/state-machine.md holds them.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from ramp.statemachine.activity import Executive
from ramp.statemachine.diagram import mermaid, states_table
from ramp.statemachine.mission import Mission


def _no_robot() -> None:
    """Drawing a machine moves nothing."""


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m ramp.statemachine",
        description="Print the RMC mission's state machine, drawn from the machine itself.")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--mermaid", action="store_true",
                      help="the state diagram as a mermaid stateDiagram-v2")
    what.add_argument("--states", action="store_true",
                      help="the table of states as markdown")
    args = parser.parse_args(argv)
    if args.mermaid:
        print(mermaid(Mission(Executive(), _no_robot).machine), end="")
    else:
        print(states_table(), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The ``safenav`` command line."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence

from safenav.errors import SafeNavError
from safenav.robot import PRESET_NAMES, preset


def _demo(args: argparse.Namespace) -> int:
    print("safenav presets (DESIGN.md section 3):")
    for name in PRESET_NAMES:
        robot = preset(name)
        scan = robot.scan()
        front = scan.beam_index(0.0)
        print(f"  {name:10s} radius {robot.radius:.3f} m, v <= {robot.v_max} m/s, {scan!r}; front beam {front}, "
              f"behind {'not covered' if scan.beam_index(math.pi) is None else scan.beam_index(math.pi)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="safenav", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    demo = commands.add_parser("demo", help="the three tutorial robots and their lidar conventions")
    demo.set_defaults(handler=_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args))
    except SafeNavError as error:
        print(f"safenav: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

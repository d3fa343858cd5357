"""The ``yarnfit`` command line.

Units at this edge follow textile labels (g/m², threads per cm, gf·cm²/cm); everything behind it is
SI. Commands are added stage by stage (``yarnfit relax``, ``yarnfit fit``, ``yarnfit export``,
``yarnfit validate``).
"""

from __future__ import annotations

import argparse
import sys

from . import __version__


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="yarnfit",
        description=(
            "Real fabric parameters for MuJoCo cloth: from a fabric's label (fibre, knit or weave, "
            "g/m², threads or stitches per cm) to a fitted orthotropic StVK shell, via a yarn-level "
            "simulation of the fabric's periodic repeat."
        ),
    )
    parser.add_argument("--version", action="version", version=f"yarnfit {__version__}")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    parser.parse_args(argv)
    parser.print_help()
    return 0


if __name__ == "__main__":
    sys.exit(main())

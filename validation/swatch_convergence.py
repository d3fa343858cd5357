"""Swatch-size convergence of the explicit yarn-level stretch test (issue 14, item 4).

For a material file, cut strips of several sizes (gauge × width between the jaws, in repeats of
the larger repeat side; each jaw band half a repeat) along each direction, pull each to 2, 5 and
10 % (:func:`yarnfit.validate.swatch.stretch_swatch`, converged solves warm-started one from the
next) and print, per direction and size: nodes, force per width (N/m) and compression ratio at each
strain, and the slowest strain's solve time (one core). The sizes are not shrunk to the suite's
node budget (:data:`yarnfit.validate.swatch.MAX_NODES`): this script is what says how large a strip
has to be.

    python validation/swatch_convergence.py MATERIAL.json [--sizes 2x1.5,4x3,8x6] \\
        [--directions weft,warp,bias] [--json OUT.json]

The force and width measured at mid-length converge as the cut loops at the long sides and the
jaws' constraint become a smaller part of the strip; the table shows how fast.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numba

from yarnfit.material_file import MaterialFile
from yarnfit.relax import relax
from yarnfit.engine import QuasiStaticOptions
from yarnfit.validate.swatch import STRAINS, SWATCH_OPTIONS, cut_swatch, stretch_swatch

# Jaw band in repeats of the larger repeat side (as the suite's strips).
CLAMP_REPEATS = 0.5
# Newton iterations per strain: the suite's limit (400) stops a large knit strip at 10 % short of
# convergence (cotton jersey, 4 × 3 repeats: force residual 7e-2 after 400); a convergence study
# must not mix converged and unconverged forces.
MAX_ITERATIONS = 3000


OPTIONS = QuasiStaticOptions(**{**SWATCH_OPTIONS, "max_iterations": MAX_ITERATIONS})


def parse_sizes(text: str) -> list[tuple[float, float]]:
    sizes = []
    for item in text.split(","):
        try:
            gauge, width = (float(v) for v in item.lower().split("x"))
        except ValueError:
            raise SystemExit(f"--sizes: {item!r} is not GAUGExWIDTH (repeats), e.g. 4x3") from None
        if not (gauge > 0 and width > 0):
            raise SystemExit(f"--sizes: {item!r} must be positive")
        sizes.append((gauge, width))
    return sizes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("material", help="a material file written by `yarnfit fit`")
    parser.add_argument("--sizes", default="2x1.5,4x3,8x6", help="gauge x width between the jaws, in repeats")
    parser.add_argument("--directions", default="weft,warp", help="comma-separated: weft, warp, bias")
    parser.add_argument("--json", help="also write the curves to this file")
    args = parser.parse_args(argv)
    numba.set_num_threads(1)  # one core, as the bench figures
    file = MaterialFile.read(args.material)
    relaxed = file.relaxed_repeat()
    if relaxed is None:
        print(f"{args.material} keeps no relaxed repeat: relaxing {file.fabric().name} again", flush=True)
        relaxed = relax(file.fabric())
    repeat = float(max(relaxed.repeat_size))
    section = relaxed.yarn.section()
    rows, curves = [], {}
    for direction in args.directions.split(","):
        for gauge, width in parse_sizes(args.sizes):
            swatch = cut_swatch(relaxed.model, relaxed.state.node_position, section, direction=direction,
                                gauge=gauge * repeat, width=width * repeat, clamp=CLAMP_REPEATS * repeat)
            start = time.perf_counter()
            curve = stretch_swatch(swatch, STRAINS, options=OPTIONS, progress=lambda text: print("   ", text, flush=True))
            label = f"{direction} {gauge:g}x{width:g}"
            curves[label] = curve
            points = curve["points"][1:]
            row = (f"| {direction} | {gauge:g} × {width:g} | {curve['nodes']} | "
                   + " | ".join(f"{p['force_n_per_m']:.4g}" for p in points) + " | "
                   + " | ".join(f"{p['compression_ratio']:.3f}" for p in points) + " | "
                   + f"{max(p['seconds'] for p in points):.1f} | {'yes' if curve['converged'] else 'NO'} |")
            rows.append(row)
            print(row, f"({time.perf_counter() - start:.0f} s)", flush=True)
    strains = " | ".join(f"{100 * e:g} %" for e in STRAINS)
    print(f"\n{relaxed.name}: repeat {1e3 * relaxed.repeat_size[0]:.3g} × {1e3 * relaxed.repeat_size[1]:.3g} mm\n")
    print(f"| direction | repeats (gauge × width) | nodes | N/m at {strains} | compression at {strains} "
          f"| slowest strain (s) | converged |")
    print("|" + "---|" * 11)
    print("\n".join(rows))
    if args.json:
        with open(args.json, "w") as out:
            json.dump({"material": relaxed.name, "curves": curves}, out, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

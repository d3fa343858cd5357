"""The ``yarnfit`` command line.

Units at this edge follow textile labels (g/m², threads or stitches per cm, mm, µm); everything
behind it is SI. Errors in the input print one line and exit with status 2; a relaxation that does
not converge prints its residuals and exits with status 1.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from . import __version__

EXIT_FAILED = 1
EXIT_USAGE = 2


class UsageError(Exception):
    """Bad input: printed as one line, exit status 2."""


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
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    commands.add_parser("materials", help="list the built-in fibres and fabric presets",
                        description="List the built-in fibres (one line each) and the fabric presets.")
    commands.add_parser("patterns", help="list the named weaves and knits",
                        description="List the named weaves and knits (one line each).")

    relax = commands.add_parser(
        "relax",
        help="relax a fabric's periodic yarn repeat (phase 1)",
        description=(
            "Build a fabric's periodic yarn repeat from its label and relax it at the yarn level "
            "(rest lengths shortened by 0.8 for knits, 0.9 for wovens, contacts with all periodic "
            "images), then print a summary. Give a preset, or --fiber with --pattern and --gsm, or "
            "--pattern-file (a .pyp file; without --gsm/--counts it keeps the file's radius, repeat "
            "and rest lengths)."
        ),
    )
    relax.add_argument("preset", nargs="?", help="a built-in fabric (see `yarnfit materials`)")
    add_fabric_arguments(relax)
    relax.add_argument("--name", help="label for the output files (default: preset, pattern or file name)")
    relax.add_argument("--rerun", metavar="FILE.rrd", help="Rerun recording of the relaxation (default: logs/<name>.rrd)")
    relax.add_argument("-o", "--output", metavar="FILE.pyp", help="write the relaxed repeat as a .pyp file")
    return parser


def add_fabric_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fiber", help="fibre name (see `yarnfit materials`)")
    parser.add_argument("--fiber-file", metavar="FIBER.json",
                        help="a fibre of your own as JSON (keys: name, density_kg_m3, young_min_pa, young_max_pa, "
                             "breaking_strain, poisson, friction)")
    parser.add_argument("--pattern", help="named weave or knit (see `yarnfit patterns`)")
    parser.add_argument("--pattern-file", metavar="FILE.pyp", help="a periodic yarn pattern in the .pyp format")
    parser.add_argument("--gsm", type=float, metavar="G", help="areal density in g/m²")
    parser.add_argument("--counts", metavar="AxB",
                        help="per cm: ends x picks for wovens, courses x wales for knits (e.g. 30x25)")


def fabric_from_arguments(args: argparse.Namespace):
    """The :class:`~yarnfit.fabric.Fabric` an argument namespace describes (UsageError if it
    describes none)."""
    from .fabric import Fabric
    from .materials import get_fiber, load_fiber_file

    counts = parse_counts(args.counts) if args.counts is not None else None
    if args.gsm is not None and not (math.isfinite(args.gsm) and args.gsm > 0):
        raise UsageError(f"--gsm must be a positive areal density in g/m², got {args.gsm:g}")
    if args.preset is not None:
        if any(v is not None for v in (args.fiber, args.fiber_file, args.pattern, args.pattern_file, args.gsm, args.counts)):
            raise UsageError("a preset fixes the fabric: give either a preset or --fiber/--pattern/--gsm/--counts")
        fabric = Fabric.preset(args.preset)
        return fabric if args.name is None else _renamed(fabric, args.name)
    if (args.fiber is None) == (args.fiber_file is None):
        raise UsageError("give a preset, or exactly one of --fiber and --fiber-file")
    fiber = get_fiber(args.fiber) if args.fiber is not None else load_fiber_file(args.fiber_file)
    if (args.pattern is None) == (args.pattern_file is None):
        raise UsageError("give exactly one of --pattern and --pattern-file")
    if args.pattern_file is not None and not Path(args.pattern_file).is_file():
        raise UsageError(f"pattern file {args.pattern_file!r} does not exist")
    name = args.name or (args.pattern if args.pattern else Path(args.pattern_file).stem)
    return Fabric(
        name=name.replace("/", "-"),
        fiber=fiber,
        structure=args.pattern,
        areal_density=None if args.gsm is None else args.gsm * 1e-3,
        counts=counts,
        pattern_file=args.pattern_file,
    )


def parse_counts(text: str) -> tuple[float, float]:
    """``"AxB"`` per cm → ``(A, B)`` per metre."""
    parts = text.lower().replace("×", "x").split("x")
    try:
        a, b = (float(p) for p in parts)
    except ValueError:
        raise UsageError(f"--counts must look like 30x25 (per cm), got {text!r}") from None
    if not (math.isfinite(a) and math.isfinite(b) and a > 0 and b > 0):
        raise UsageError(f"--counts must be two positive numbers per cm, got {text!r}")
    return a * 100.0, b * 100.0


def _renamed(fabric, name: str):
    from dataclasses import replace

    return replace(fabric, name=name)


# -- commands ---------------------------------------------------------------------------------


def cmd_materials(args: argparse.Namespace) -> int:
    from .fabric import PRESETS
    from .materials import FIBERS

    print("fibres:")
    for fiber in FIBERS.values():
        print("  " + fiber.describe())
    print("presets (yarnfit relax <preset>):")
    for name, p in PRESETS.items():
        print(f"  {name:<17} {p.fiber:<9} {p.pattern:<9} {p.gsm:5.0f} g/m²  {p.counts_per_cm[0]:g}x{p.counts_per_cm[1]:g}/cm  ({p.note})")
    return 0


def cmd_patterns(args: argparse.Namespace) -> int:
    from .fabric import DEFAULT_COUNTS_PER_CM
    from .patterns import DRAFTS, STITCHES

    for name, draft in DRAFTS.items():
        a, b = DEFAULT_COUNTS_PER_CM[name]
        print(f"{name:<11} woven  {draft.shape[1]} ends × {draft.shape[0]} picks per repeat; typical {a:g}x{b:g} ends x picks/cm")
    for name, chart in STITCHES.items():
        a, b = DEFAULT_COUNTS_PER_CM[name]
        print(f"{name:<11} knit   {chart.shape[0]} courses × {chart.shape[1]} wales per repeat; typical {a:g}x{b:g} courses x wales/cm")
    print("any .pyp file (--pattern-file), e.g. the HYLC patterns (Sperl, Narain, Wojtan 2020)")
    return 0


class ProgressLine:
    """One status line, rewritten in place on a terminal, printed every few seconds otherwise."""

    def __init__(self, stream=sys.stderr, every: float = 2.0):
        self.stream = stream
        self.tty = stream.isatty()
        self.every = every
        self.start = time.perf_counter()
        self.last = -math.inf
        self.relaxation = 0

    def start_relaxation(self, pattern) -> None:
        self.relaxation += 1
        self._write(f"relaxation {self.relaxation}: radius {pattern.radius * 1e6:.2f} µm, "
                    f"{pattern.n_nodes} nodes, {_plural(len(pattern.yarns()), 'yarn')}", force=True)

    def __call__(self, progress) -> None:
        r = progress.residual
        self._write(f"relaxation {self.relaxation} iteration {progress.iteration:4d}: force {r.force:.1e}, "
                    f"torque {r.torque:.1e}, penetration {r.penetration:.1e}  "
                    f"[{time.perf_counter() - self.start:.1f} s]")

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()

    def _write(self, text: str, force: bool = False) -> None:
        now = time.perf_counter()
        if self.tty:
            self.stream.write("\r\033[K" + text)
            self.stream.flush()
        elif force or now - self.last >= self.every:
            self.stream.write(text + "\n")
            self.stream.flush()
            self.last = now


def cmd_relax(args: argparse.Namespace) -> int:
    from .patterns import write_pyp
    from .record import RelaxRecording
    from .relax import OVERLAP_TOLERANCE, relax

    fabric = fabric_from_arguments(args)
    path = Path(args.rerun) if args.rerun else Path("logs") / f"{fabric.name}.rrd"
    recording = None  # opened once the fabric has given a valid pattern: bad input writes no file
    line = ProgressLine()

    def on_start(pattern):
        nonlocal recording
        if recording is None:
            recording = RelaxRecording(fabric.name, path)
        recording.start(pattern)
        line.start_relaxation(pattern)

    def progress(p):
        recording(p)
        line(p)

    result = relax(fabric, progress=progress, on_start=on_start)
    line.close()
    recording.finish(result)
    if args.output:
        write_pyp(result.relaxed_pattern(), args.output)
    print(relax_summary(result, fabric, path, args.output))
    if not result.converged:
        print(f"yarnfit: the relaxation did not converge: {result.residual}", file=sys.stderr)
        return EXIT_FAILED
    if not result.valid:
        print(f"yarnfit: yarns overlap by {100 * result.penetration:.3g} % of the diameter after relaxation "
              f"(tolerance {100 * OVERLAP_TOLERANCE:g} %)", file=sys.stderr)
        return EXIT_FAILED
    return 0


def relax_summary(result, fabric, recording_path, output) -> str:
    px, py = result.repeat_size
    lines = [
        f"{result.name}: {fabric.fiber.name}, {result.pattern.family}, {_plural(len(result.pattern.yarns()), 'yarn')}, "
        f"{result.model.n_nodes} nodes",
        f"  repeat            {px * 1e3:.4g} mm × {py * 1e3:.4g} mm",
        f"  yarn radius       {result.radius * 1e6:.4g} µm",
        f"  yarn per area     {result.yarn_length_per_area:.5g} m/m²",
        f"  areal density     {result.areal_density * 1e3:.4g} g/m²",
        f"  residual          force {result.residual.force:.2e}, torque {result.residual.torque:.2e}, "
        f"energy change {result.residual.energy_change:.2e}",
        f"  worst overlap     {result.penetration * 100:.3g} % of the diameter",
        f"  converged         {'yes' if result.converged else 'NO'} ({result.iterations} iterations, "
        f"{_plural(result.relaxations, 'relaxation')})",
        f"  time              {result.seconds:.2f} s",
        f"  recording         {recording_path}",
    ]
    if output:
        lines.append(f"  relaxed repeat    {output}")
    return "\n".join(lines)


def _plural(count: int, noun: str) -> str:
    return f"{count} {noun}{'' if count == 1 else 's'}"


COMMANDS = {"materials": cmd_materials, "patterns": cmd_patterns, "relax": cmd_relax}


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    from .patterns import PatternError

    try:
        return COMMANDS[args.command](args)
    except (UsageError, PatternError, ValueError, OSError) as error:
        message = str(error).splitlines()[0] if str(error) else type(error).__name__
        print(f"yarnfit {args.command}: error: {message}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())

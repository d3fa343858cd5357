"""Swatch-size convergence of the explicit yarn-level stretch test (issue 14, item 4).

For a material file, cut strips of several sizes (gauge × width between the jaws, in repeats of
the larger repeat side; each jaw band half a repeat) along each direction, pull each to 2, 5 and
10 % (:func:`yarnfit.validate.swatch.stretch_swatch`, converged solves warm-started one from the
next) and print, per direction and size: nodes, force per width (N/m) on the jaws and carried by
the strip's middle half of the width across its middle half of the gauge (where it is furthest
from its cut sides and jaws: :func:`yarnfit.validate.strip.cut_forces`), the same middle half's
pull and width read at its own 2, 5 and 10 % (the reading the verdicts below use:
:func:`yarnfit.validate.swatch.read_uniform`), compression ratio at each strain, the strain of
the strip's middle half read between two marks as an extensometer reads it
(:func:`yarnfit.validate.strip.mid_strain`: where it differs from the nominal strain, the jaws
constrain the strip), and the slowest strain's solve time (one core). The sizes are not shrunk to the suite's
node budget (:data:`yarnfit.validate.swatch.MAX_NODES`): this script is what says how large a strip
has to be.

    python validation/swatch_convergence.py MATERIAL.json [--sizes 2x1.5,4x3,8x6 (bias: 3x1,6x2,12x4)] \\
        [--directions weft,warp,bias,other bias] [--selvedge] [--frictionless] [--json OUT.json] [--checkpoints DIR] \\
        [--from-json A.json,B.json] [--kept]

The force and width measured at mid-length converge as the cut loops at the long sides and the
jaws' constraint become a smaller part of the strip; the table shows how fast. Its edge draw-in
(:func:`yarnfit.validate.strip.edge_draw_in`) is how far the yarn ends cut at the long sides have
slid in beyond the strip's narrowing: yarn a frictionless cut strip feeds to its loops from its
free ends, which a periodic repeat cannot. The strips are pulled with Coulomb friction at the yarn
crossings, as the suite's yarn scene pulls them (the fibre's coefficient, lagged per strain:
:mod:`yarnfit.engine.friction`), which holds those ends as a real strip's are held;
``--frictionless`` pulls them without.

Then the material's shell (nonlinear) and its linear fit from the same samples (``fit.linear``)
against the largest strip of each direction (issue 14's acceptance): a long strip of the shell
pulled at the strip's angle with every other stress free
(:meth:`yarnfit.shell.ShellMaterial.uniaxial_pull`), force per width and width ratio, with a
verdict (force within SHELL_FORCE_RTOL, width ratio within SHELL_COMPRESSION_ATOL), the strip read
three ways (READINGS): at its jaws (their pull over the whole width at their travel, the whole
width at mid-length); where it is uniform, as issue 14 asks it measured (the middle half's pull
at the strain the strip's middle reached at each level, the middle half's width); and the same at
the nominal strains themselves, read off the middle's curve between its load steps
(:func:`yarnfit.validate.swatch.read_uniform`; between the levels alone for curves written before
the steps were kept, which the table says). Beside them the periodic
repeat pulled the same way along weft, warp and bias (:func:`yarnfit.homogenize.periodic_pull`:
the limit a frictionless strip would tend to as it widens, and what the shell is fitted to), the
same pull with the fibre's friction, in load steps as the strip is pulled
(:func:`yarnfit.homogenize.frictional_periodic_pull`: what a frictional strip tends to; its own
count says how many points it meets with the shell's criteria), and then the shell against the
frictionless pull at the nominal strains: the fit's own error, told apart from the strip's size.
The shell strip between the same jaws is also set against the shell pulled free (its jaws' hold):
where the jaws move the shell's own reading by more than the shell criterion, the strip is not a
representative test of the material there (a woven's bias strip shorter than about twice its
width, whose middle the jaws hold: a bias extension test's gauge is 2-3 widths), and its cells are
counted apart.
``--from-json`` reads curves written by earlier runs instead of solving (runs of several sizes or
directions made in parallel). The largest strips take hours a level, so their curves are kept in
``validation/strips/`` (each with the command and commit that solved it) and read against every
later fit: ``--kept`` reads every one of the material's (``--from-json`` names files; a curve of
another fabric is refused).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import subprocess
import sys
import time

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from yarnfit.material_file import MaterialFile
from yarnfit.engine import QuasiStaticOptions
from yarnfit.homogenize import periodic_pulls_along
from yarnfit.validate.checkpoint import CheckpointError
from yarnfit.validate.shell_strip import ShellStripCurve, shell_strip_limit
from yarnfit.validate import PULL_DIRECTIONS
from yarnfit.validate.swatch import STRAINS, SWATCH_OPTIONS, cut_swatch, read_uniform, stretch_swatch, swatch_curve
from yarnfit.validate.verdicts import JAWS_HOLD_RTOL
from yarnfit.tasks import one_core

# Jaw band in repeats of the larger repeat side (as the suite's strips).
CLAMP_REPEATS = 0.5
# Newton iterations per strain: the suite's limit (400) stops a large knit strip at 10 % short of
# convergence (cotton jersey, 4 × 3 repeats: force residual 7e-2 after 400); a convergence study
# must not mix converged and unconverged forces.
MAX_ITERATIONS = 3000


OPTIONS = QuasiStaticOptions(**{**SWATCH_OPTIONS, "max_iterations": MAX_ITERATIONS})
# Issue 14's criteria for the shell against the yarn-level swatch: force per width within 20 %,
# compression ratio within 0.05.
SHELL_FORCE_RTOL = 0.2
SHELL_COMPRESSION_ATOL = 0.05
# The shell strip is pulled on past the last level to this jaw strain, so that it is read at the
# strain a yarn strip's middle reached: 12.6-13.3 % for the knits at 10 %, 15.1 % for the twill's
# bias strip, whose shell strips' middles strain less or more than their jaws.
SHELL_STRIP_REACH = 0.2
# A strip whose own jaws move the shell's reading by more than JAWS_HOLD_RTOL (its same-jaws strip
# against its free pull) cannot tell the shell's error from the jaws', and its cells are counted
# apart: a woven's 8 × 6 bias strip (gauge 1.33 widths) reads the twill's shell 3.2 / 5.7 / 1.9
# times its free pull at the middle's 2 / 5 / 10 %, the satin's 4.5 / 4.8 / 24 times, where a
# 12 × 4 strip (a bias extension test's 3 widths) reads both within 12 %.

# Default strips, gauge x width in repeats: along the yarns up to 8 x 6; off them a bias extension
# test's proportions (gauge three widths) at the same areas, whose middle shears out of the jaws'
# reach (above).
DEFAULT_SIZES = "2x1.5,4x3,8x6"
DEFAULT_BIAS_SIZES = "3x1,6x2,12x4"
# The directions issue 14's acceptance measures at 2, 5 and 10 % (the other bias is optional).
ACCEPTANCE_DIRECTIONS = ("weft", "warp", "bias")
# The largest strips' curves, kept in the repository (its README lists them).
KEPT_STRIPS = Path(__file__).parent / "strips"


def default_sizes(direction: str) -> list[tuple[float, float]]:
    """The strips a direction is pulled at when ``--sizes`` is not given (a direction that is not
    a key of PULL_DIRECTIONS is refused by the cut, with the names)."""
    along_yarns = PULL_DIRECTIONS.get(direction, 0.0) % 90.0 == 0.0
    return parse_sizes(DEFAULT_SIZES if along_yarns else DEFAULT_BIAS_SIZES)


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


def solve_curves(file: MaterialFile, sizes: Callable[[str], list], directions, selvedge: bool = False,
                 friction: bool = True, json_path: str | None = None,
                 checkpoints: Path | None = None) -> tuple[object, dict]:
    """``(relaxed repeat, {label: curve})``: each direction's strips at each of ``sizes(direction)`` (with
    ``selvedge``, the yarns running across a strip joined at its long sides:
    :func:`yarnfit.validate.swatch.join_selvedges`; with ``friction``, the fibre's friction at the
    contacts), pulled to STRAINS on one core; prints each strip's row as it finishes and, with
    ``json_path``, writes the curves there after every strain a strip reaches (a strip takes up to
    hours: a run stopped part way keeps the strains it reached, the strip being pulled marked
    ``"unfinished"``, for ``--from-json``). With ``checkpoints`` (a folder), each strip's pull
    writes where it stands there after every load step and resumes from it when run again
    (:class:`yarnfit.validate.checkpoint.PullCheckpoint`): a level of hours can be solved over
    several runs."""
    provenance()  # the commit the run starts at (the code it runs), not whatever HEAD is an hour later
    relaxed = file.relaxed_or_relaxed_again(lambda text: print(text, flush=True))
    repeat = float(max(relaxed.repeat_size))
    section = relaxed.yarn.section()
    coefficient = file.fabric().fiber.friction if friction else 0.0
    curves = {}
    for direction in directions:
        for gauge, width in sizes(direction):
            swatch = cut_swatch(relaxed.model, relaxed.state.node_position, section, direction=direction,
                                gauge=gauge * repeat, width=width * repeat, clamp=CLAMP_REPEATS * repeat,
                                selvedge=selvedge)
            label, points = f"{direction} {gauge:g}x{width:g}", []

            def keep(k, strain, position, point, swatch=swatch, label=label, points=points, size=(gauge, width)):
                """Write the strip's curve so far after each strain it reaches before its last (the
                finished curve is written below)."""
                points.append(point)
                if json_path and 0 < k < len(STRAINS):
                    write_curves(json_path, relaxed.name,
                                 {**curves, label: {**swatch_curve(swatch, points), "repeats": list(size),
                                                    "written_by": provenance(), "unfinished": True}})

            start = time.perf_counter()
            checkpoint = None if checkpoints is None else \
                checkpoints / f"{relaxed.name}_{direction.replace(' ', '-')}_{gauge:g}x{width:g}.npz"
            curve = stretch_swatch(swatch, STRAINS, options=OPTIONS, friction=coefficient, on_step=keep,
                                   progress=lambda text: print("   ", text, flush=True),
                                   step_progress=lambda text: print("     ", text, flush=True),
                                   checkpoint=checkpoint)
            curve["repeats"] = [gauge, width]
            curve["written_by"] = provenance()
            curves[label] = curve
            print(convergence_row(curve), f"({time.perf_counter() - start:.0f} s)", flush=True)
            if json_path:
                write_curves(json_path, relaxed.name, curves)
    return relaxed, curves


def read_curves(paths: list[str], name: str) -> dict:
    """The curves in the files ``paths`` (as :func:`write_curves` writes them), by label, each of
    which must be of the material ``name``: a curve of another fabric read against this shell
    would judge it against someone else's yarns. Raises ``ValueError`` naming the file."""
    curves = {}
    for path in paths:
        with open(path) as source:
            data = json.load(source)
        if data.get("material") != name:
            raise ValueError(f"{path}: its curves are of {data.get('material')!r}, not of the material {name!r}")
        for label, curve in data["curves"].items():
            # Labels are "DIRECTION GAUGExWIDTH" (curves written before "repeats" was kept).
            curve.setdefault("repeats", parse_sizes(label.split()[1])[0])
            curves[label] = curve
    return curves


def kept_curves(name: str) -> list[str]:
    """The curve files kept in :data:`KEPT_STRIPS` for the material ``name`` (by the file's
    ``material``), sorted. Raises ``ValueError`` when it keeps none."""
    paths = []
    for path in sorted(KEPT_STRIPS.glob("*.json")):
        with open(path) as source:
            if json.load(source).get("material") == name:
                paths.append(str(path))
    if not paths:
        raise ValueError(f"{KEPT_STRIPS} keeps no strip curve of {name!r}")
    return paths


def write_curves(path: str, name: str, curves: dict) -> None:
    """The curves as ``--from-json`` reads them (each with what solved it: :func:`provenance`)."""
    with open(path, "w") as out:
        json.dump({"material": name, "curves": curves}, out, indent=1)


@functools.cache
def provenance() -> dict:
    """The command that solved the curves and the yarnfit commit it ran (``None`` outside a git
    checkout): a strip takes hours, so its curve is kept (``validation/strips/``) and read again
    against later fits, and it is only as good as the yarn model that solved it."""
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).resolve().parent,
                                capture_output=True, text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = None
    return {"command": " ".join(["python validation/swatch_convergence.py", *sys.argv[1:]]), "commit": commit,
            "date": time.strftime("%Y-%m-%d")}


def convergence_header() -> list[str]:
    """The convergence table's header cells, one per :func:`convergence_row` cell group (a group
    over STRAINS is one cell whose strains are joined by ``" | "``)."""
    strains = " | ".join(f"{100 * e:g} %" for e in STRAINS)
    return ["direction", "repeats (gauge × width)", "nodes", f"N/m (jaws) at {strains}",
            f"N/m (middle half) at {strains}", f"N/m where uniform (the middle half's, at its own {strains})",
            f"its width ratio at {strains}", f"compression at {strains}", f"middle half's compression at {strains}",
            f"middle's strain (%) at {strains}", f"edge draw-in (µm) at {strains}",
            f"N/m per quarter of the width at {100 * STRAINS[-1]:g} %", "slowest strain (s)", "converged"]


def convergence_row(curve: dict) -> str:
    """The strip's row of the convergence table; '—' at the strains a stopped run did not reach (and,
    where uniform, those its middle did not reach)."""
    points = level_points(curve)
    reached = [p for p in points if p is not None]
    gauge, width = curve["repeats"]

    def cells(text: Callable[[dict], str]) -> str:
        return " | ".join("—" if p is None else text(p) for p in points)

    def uniform_cells(text: Callable[[ReadPoint], str]) -> str:
        return " | ".join("—" if r is None else text(r) for r in uniform)

    last, uniform = points[-1], _uniform(curve)
    converged = "unfinished" if curve.get("unfinished") else "yes" if curve["converged"] else "NO"
    return (f"| {curve['direction']} | {gauge:g} × {width:g} | {curve['nodes']} | "
            + cells(lambda p: f"{p['force_n_per_m']:.4g}") + " | "
            + cells(lambda p: _force(p.get("middle_force_n_per_m"))) + " | "
            + uniform_cells(lambda r: f"{r.force:.4g}{r.note}") + " | "
            + uniform_cells(lambda r: f"{r.compression:.3f}") + " | "
            + cells(lambda p: f"{p['compression_ratio']:.3f}") + " | "
            + cells(lambda p: _ratio(p.get("middle_compression_ratio"))) + " | "
            + cells(lambda p: _percent(p.get("mid_strain"))) + " | "
            + cells(lambda p: _micrometres(p.get("edge_draw_in_m"))) + " | "
            + ("—" if last is None else _quarters(last.get("quarter_forces_n_per_m"))) + " | "
            + f"{max((p['seconds'] for p in reached), default=0.0):.1f} | {converged} |")


def level_points(curve: dict) -> list[dict | None]:
    """The strip's point at each of STRAINS, ``None`` where a stopped run did not reach it."""
    points = curve["points"][1:]
    if len(points) > len(STRAINS) or any(p["strain"] != e for p, e in zip(points, STRAINS)):
        raise ValueError(f"the curve's strains {[p['strain'] for p in points]} are not a start of {list(STRAINS)}")
    return points + [None] * (len(STRAINS) - len(points))


def _quarters(values) -> str:
    """The pull per quarter of the width (N/m, from −y), for the table; '—' for an older run."""
    return "—" if values is None else " / ".join(f"{v:.3g}" for v in values)


def _force(value) -> str:
    """A force per width in N/m for the table; '—' where it is not known (an older run)."""
    return "—" if value is None else f"{value:.4g}"


def _ratio(value) -> str:
    """A width ratio for the table; '—' where it is not known (an empty mark, or an older run)."""
    return "—" if value is None else f"{value:.3f}"


def middle_compression(point: dict) -> float:
    """The strip's width ratio where it is uniform: its middle half's, between two material marks
    (:func:`yarnfit.validate.strip.middle_compression`), or the whole width's at mid-length where
    a mark held no node (or for curves written before it was measured)."""
    value = point.get("middle_compression_ratio")
    return point["compression_ratio"] if value is None else value


def middle_force(point: dict) -> float:
    """The strip's force per width where it is uniform: its middle half's pull across planes over
    the middle half of the gauge (:func:`yarnfit.validate.strip.cut_forces`), or the jaws' for
    curves written before it was measured."""
    value = point.get("middle_force_n_per_m")
    return point["force_n_per_m"] if value is None else value


def _percent(value) -> str:
    """A strain in % for the table; '—' where it is not known (an empty mark, or an older run)."""
    return "—" if value is None else f"{100 * value:.3g}"


def _micrometres(value) -> str:
    """A length in µm for the table; '—' where it is not known (no end cut there, or an older run)."""
    return "—" if value is None else f"{1e6 * value:.3g}"


def frictional_pulls(relaxed, curves: dict, reading: "Reading", coefficient: float) -> dict:
    """``{(direction, strain): PeriodicPull}``: the periodic repeat pulled along weft, warp or
    the bias with the fibre's friction ``coefficient`` to each strain ``reading`` takes the largest
    strip's points to, along one load path per direction as a strip is pulled
    (:func:`yarnfit.homogenize.frictional_periodic_pull`,
    :func:`~yarnfit.homogenize.frictional_periodic_bias_pull`); none without friction."""
    pulls = {}
    if coefficient <= 0.0:
        return pulls
    for direction, curve in largest_strips(curves).items():
        strains = sorted({point.strain for point in reading.read(curve) if point is not None})
        path = periodic_pulls_along(relaxed, direction, strains, coefficient)
        for pull in path:
            pulls[direction, pull.strain] = pull
    return pulls


def periodic_pulls(relaxed, directions) -> dict:
    """``{(direction, strain): PeriodicPull}``: the frictionless periodic pulls along each of
    ``directions`` at each of STRAINS (:func:`yarnfit.homogenize.periodic_pulls_along`)."""
    return {(direction, pull.strain): pull
            for direction in directions for pull in periodic_pulls_along(relaxed, direction, STRAINS)}


def _against(value: float, reference: float) -> str:
    ratio = value / reference if reference > 0 else math.inf
    return f"{value:.4g} ({100 * (ratio - 1.0):+.0f} %)"


def middle_strain(point: dict) -> float:
    """The strain of the strip's middle as its extensometer reads it
    (:func:`yarnfit.validate.strip.mid_strain`), or the nominal strain where no mark held a node
    (or for curves written before it was measured)."""
    value = point.get("mid_strain")
    return point["strain"] if value is None else value


@dataclass(frozen=True)
class ReadPoint:
    """One row of a strip's reading: the ``level`` it stands for (the jaws' strain, or the middle's
    strain it was read at), the strip's ``force`` per width (N/m), the ``strain`` the free pulls
    are taken to, its width ratio ``compression``, whether it ``converged``, and a ``note`` for
    the strain's cell."""

    level: float
    force: float
    strain: float
    compression: float
    converged: bool
    note: str = ""


@dataclass(frozen=True)
class Reading:
    """How a strip's pull is read for the verdict: ``read(curve)`` gives its rows
    (:class:`ReadPoint`, or ``None`` for a strain it cannot be read at)."""

    name: str
    title: str
    read: Callable[[dict], list]


def _jaws(curve: dict) -> list[ReadPoint | None]:
    return [None if p is None else ReadPoint(p["strain"], p["force_n_per_m"], p["strain"], p["compression_ratio"],
                                             p["converged"]) for p in level_points(curve)]


def _middle(curve: dict) -> list[ReadPoint | None]:
    return [None if p is None else ReadPoint(p["strain"], middle_force(p), middle_strain(p), middle_compression(p),
                                             p["converged"]) for p in level_points(curve)]


def _uniform(curve: dict) -> list[ReadPoint | None]:
    rows = []
    for read in read_uniform(curve, STRAINS):
        note = "" if read is None else (" (between levels)" if read.source == "levels" else "") + (
            " (extrapolated)" if read.extrapolated else "")
        rows.append(None if read is None else ReadPoint(read.strain, read.force_n_per_m, read.strain,
                                                        read.compression_ratio, read.converged, note))
    return rows


READINGS = (
    # As a tensile tester without extensometers reads a strip: the jaws' force over the whole
    # width, at the jaws' travel, and the whole width at mid-length.
    Reading("jaws", "the jaws' pull over the whole width at the jaws' strain, the whole width at mid-length", _jaws),
    # Where the strip is uniform (issue 14): the middle half's pull at the strain its middle
    # reached, the middle half's width (a strip's jaws hold its ends unsheared and unnarrowed, so
    # its middle strains more than their travel; a knit's cut sides, drawn in, carry little and
    # narrow the whole width far more).
    Reading("middle", "the middle half's pull at the strain of the strip's middle, the middle half's width",
            _middle),
    # The same, at the nominal strains themselves: read off the middle's curve where its strain
    # was 2, 5 and 10 % (yarnfit.validate.swatch.read_uniform), as a tensile tester with an
    # extensometer reads a force at a strain. (A knit's middle strains 12-13 % at the 10 % level,
    # beyond the uniaxial samples; this row is read where the fit has samples.)
    Reading("uniform", "the middle half's pull and width at the nominal strains of the strip's middle "
            "(read off its curve between load steps)", _uniform),
)


def largest_strips(curves: dict) -> dict:
    """``{direction: curve}``: the strip of each direction with the most nodes."""
    largest = {}
    for curve in curves.values():
        if curve["nodes"] > largest.get(curve["direction"], {"nodes": -1})["nodes"]:
            largest[curve["direction"]] = curve
    return largest


def unreached_cells(curves: dict) -> list[str]:
    """Issue 14's cells (weft, warp and bias at each of STRAINS) that the largest strip of their
    direction has not reached, or that no strip measures: ``"DIRECTION LEVEL %"`` each."""
    largest = largest_strips(curves)
    cells = []
    for direction in ACCEPTANCE_DIRECTIONS:
        points = level_points(largest[direction]) if direction in largest else [None] * len(STRAINS)
        cells += [f"{direction} {100 * e:g} %" for e, point in zip(STRAINS, points) if point is None]
    return cells


def shell_strips(file: MaterialFile, curves: dict) -> dict[str, ShellStripCurve]:
    """``{direction: curve}``: the nonlinear shell pulled between the jaws of the largest strip of
    each direction, its gauge and width, to STRAINS and on to SHELL_STRIP_REACH
    (:func:`yarnfit.validate.shell_strip.shell_strip_limit`: the same test as the yarn strip's,
    read the same way)."""
    strips = {}
    for direction, curve in largest_strips(curves).items():
        start = time.perf_counter()
        strains = (*STRAINS, SHELL_STRIP_REACH)
        strips[direction] = shell_strip_limit(file.shell, curve["angle_deg"], curve["gauge_m"], curve["width_m"],
                                              strains, progress=lambda text: print("   ", text, flush=True))
        print(f"shell strip {direction} ({strips[direction].nodes} nodes, rows {strips[direction].rows}): "
              f"{time.perf_counter() - start:.0f} s", flush=True)
    return strips


@dataclass(frozen=True)
class Tally:
    """Of a reading's converged points: how many were judged and how many the nonlinear shell
    meets pulled free (``within``), how many its shell strip between the same jaws was judged at
    and meets, how many frictional periodic pulls were judged and meet, and how many of the
    strip's judged points were representative (the jaws move the shell strip's reading by at most
    JAWS_HOLD_RTOL of its free pull) and met there."""

    judged: int = 0
    within: int = 0
    strip_judged: int = 0
    strip_within: int = 0
    rubbed: int = 0
    rubbed_within: int = 0
    representative: int = 0
    representative_within: int = 0


def _meets(force: float, compression: float, reference_force: float, reference_compression: float) -> bool:
    ratio = force / reference_force if reference_force > 0 else math.inf
    return abs(ratio - 1.0) <= SHELL_FORCE_RTOL and abs(compression - reference_compression) <= SHELL_COMPRESSION_ATOL


def shell_rows(file: MaterialFile, curves: dict, reading: Reading, periodic: Callable,
               frictional: dict, strips: dict[str, ShellStripCurve]) -> tuple[list[str], Tally]:
    """Table rows of the shell (nonlinear and linear) pulled free, the nonlinear shell's strip
    between the same jaws (``strips``, :func:`shell_strips`: at the jaws' level for the jaws'
    reading, else read at the strain the yarn strip's middle reached), the periodic repeat's pull
    (``periodic(direction, strain)``, a :class:`PeriodicPull` or None) and its frictional pull
    (``frictional[direction, strain]``, :func:`frictional_pulls`) against the largest strip per
    direction read by ``reading``, and their :class:`Tally`."""
    shells = {"nonlinear": file.shell, "linear": file.linear_shell}  # the linear (StVK) fit from the same samples
    rows, judged, within, rubbed, rubbed_within, strip_judged, strip_within = [], 0, 0, 0, 0, 0, 0
    representative, representative_within = 0, 0
    for direction, curve in largest_strips(curves).items():
        angle = math.radians(curve["angle_deg"])
        gauge, width = curve["repeats"]
        for level, point in zip(STRAINS, reading.read(curve)):
            if point is None:
                rows.append(f"| {direction} | {gauge:g} × {width:g} | {100 * level:g} % | — | not reached | — | "
                            + " | ".join(["— | —"] * 5) + " | — | not reached | — |")
                continue
            force, strain, narrowing = point.force, point.strain, point.compression
            pull = periodic(direction, strain)
            cells = ["— | —" if pull is None else f"{_against(pull.force_n_per_m, force)} | {pull.width_ratio:.3f}"]
            pull = frictional.get((direction, strain))
            cells.append("— | —" if pull is None else
                         f"{_against(pull.force_n_per_m, force)} | {pull.width_ratio:.3f}"
                         + ("" if pull.converged else " (not converged)"))
            if pull is not None and pull.converged and point.converged:
                rubbed += 1
                rubbed_within += _meets(pull.force_n_per_m, pull.width_ratio, force, narrowing)
            verdicts, free = {}, {}
            for name, shell in shells.items():
                pull = free[name] = shell.uniaxial_pull(angle, 1.0 + strain)
                verdicts[name] = _meets(pull.force_n_per_m, pull.width_ratio, force, narrowing)
                cells.append(f"{_against(pull.force_n_per_m, force)} | {pull.width_ratio:.3f}")
            strip = strips[direction]
            if reading.name == "jaws":
                state = strip.at_strain(point.level)
                same = (state.force_n_per_m, state.compression_ratio, state.converged)
            else:
                read = strip.read([strain])[0]
                same = None if read is None else (read.force_n_per_m, read.compression_ratio, read.converged)
            # The jaws' hold: the same-jaws strip's reading over the free pull, both the shell's.
            held = None if same is None or free["nonlinear"].force_n_per_m <= 0.0 else (
                same[0] / free["nonlinear"].force_n_per_m)
            if same is None:
                cells.append("not reached | — | —")
            else:
                cells.append(f"{_against(same[0], force)} | {same[1]:.3f}" + ("" if same[2] else " (not converged)")
                             + (" | —" if held is None else f" | {held:.3g}"))
            # The strip is judged where both it and the yarn strip converged.
            strip_meets = None if not point.converged or same is None or not same[2] else _meets(
                same[0], same[1], force, narrowing)
            if point.converged:
                judged += 1
                within += verdicts["nonlinear"]
            if strip_meets is not None:
                strip_judged += 1
                strip_within += strip_meets
                if held is not None and abs(held - 1.0) <= JAWS_HOLD_RTOL:
                    representative += 1
                    representative_within += strip_meets
            verdict = ("not converged" if not point.converged else
                       "within" if verdicts["nonlinear"] else "MISSED")
            strip_verdict = "—" if strip_meets is None else "within" if strip_meets else "MISSED"
            rows.append(f"| {direction} | {gauge:g} × {width:g} | {100 * point.level:g} % | {force:.4g} | "
                        f"{100 * strain:.3g} %{point.note} | {narrowing:.3f} | " + " | ".join(cells)
                        + f" | {verdict} | {strip_verdict} |")
    return rows, Tally(judged, within, strip_judged, strip_within, rubbed, rubbed_within, representative,
                       representative_within)


def fit_rows(file: MaterialFile, curves: dict, pulls: dict) -> list[str]:
    """Rows of the nonlinear shell against the periodic pulls at STRAINS (``pulls``, of the kind
    its samples were: frictionless, or with the friction they were loaded with): the fit's own
    error, apart from any strip's size."""
    rows = []
    for direction, curve in largest_strips(curves).items():
        angle = math.radians(curve["angle_deg"])
        for strain in STRAINS:
            nominal = pulls.get((direction, strain))
            if nominal is None:
                continue
            pull = file.shell.uniaxial_pull(angle, 1.0 + strain)
            rows.append(f"| {direction} | {100 * strain:g} % | {nominal.force_n_per_m:.4g} | "
                        f"{nominal.width_ratio:.3f} | {'yes' if nominal.converged else 'NO'} | "
                        f"{_against(pull.force_n_per_m, nominal.force_n_per_m)} | {pull.width_ratio:.3f} |")
    return rows


def table_columns(header: list[str]) -> int:
    """The columns ``header`` spans: a cell over STRAINS joins its strains with ``" | "``."""
    return sum(len(cell.split(" | ")) for cell in header)


def print_table(title: str, header: list[str], rows: list[str]) -> None:
    """A Markdown table after a blank line and its ``title`` (none if empty): ``header`` cells,
    the separator over the columns they span (:func:`table_columns`) and the ``rows`` as given."""
    print(f"\n{title}\n" if title else "")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * table_columns(header))
    print("\n".join(rows))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("material", help="a material file written by `yarnfit fit`")
    parser.add_argument("--sizes", help=f"gauge x width between the jaws, in repeats, for every direction "
                                         f"(default {DEFAULT_SIZES}; on the bias {DEFAULT_BIAS_SIZES})")
    parser.add_argument("--directions", default="weft,warp",
                        help="comma-separated: weft, warp, bias, other bias (−45°)")
    parser.add_argument("--selvedge", action="store_true",
                        help="join the yarns running across each strip at its long sides (a flat knit's selvedges)")
    parser.add_argument("--frictionless", action="store_true",
                        help="no friction at the yarn contacts (default: the fibre's coefficient, as the suite)")
    parser.add_argument("--json", help="also write the curves to this file")
    parser.add_argument("--checkpoints", help="a folder where each strip's pull is saved after every load step and "
                                              "resumed from when the same command runs again")
    parser.add_argument("--from-json", help="comma-separated curve files of earlier runs: compare, do not solve")
    parser.add_argument("--kept", action="store_true",
                        help=f"compare against every curve of this material kept in {KEPT_STRIPS.parent.name}/"
                             f"{KEPT_STRIPS.name}/ (with --from-json: those too); do not solve")
    args = parser.parse_args(argv)
    with one_core():  # as the bench figures
        file = MaterialFile.read(args.material)
        if args.from_json or args.kept:
            name = file.fabric().name
            paths = args.from_json.split(",") if args.from_json else []
            try:
                curves = read_curves(paths + (kept_curves(name) if args.kept else []), name)
            except ValueError as exc:
                print(f"swatch_convergence.py: {exc}", file=sys.stderr)
                return 2
            relaxed = file.relaxed_or_relaxed_again(lambda text: print(text, flush=True))
            if args.json:  # the curves read, together in one file
                write_curves(args.json, name, curves)
        else:
            sizes = default_sizes if args.sizes is None else (lambda direction, given=parse_sizes(args.sizes): given)
            try:
                relaxed, curves = solve_curves(file, sizes, args.directions.split(","), args.selvedge,
                                               not args.frictionless, args.json,
                                               None if args.checkpoints is None else Path(args.checkpoints))
            except CheckpointError as exc:
                print(f"swatch_convergence.py: {exc}", file=sys.stderr)
                return 2
            name = relaxed.name
            print(f"\n{name}: repeat {1e3 * relaxed.repeat_size[0]:.3g} × {1e3 * relaxed.repeat_size[1]:.3g} mm")
        order = sorted(curves.values(), key=lambda c: (c["direction"], c["nodes"]))
        print_table("", convergence_header(), [convergence_row(curve) for curve in order])
        pulls = periodic_pulls(relaxed, sorted({curve["direction"] for curve in curves.values()}))

        def periodic(direction: str, strain: float):
            """The periodic pull at ``strain``: solved at STRAINS already, else now."""
            if (direction, strain) in pulls:
                return pulls[direction, strain]
            return periodic_pulls_along(relaxed, direction, [strain])[0]

        coefficient = 0.0 if args.frictionless else relaxed.fiber.friction
        strips = shell_strips(file, curves)
        counts, rubbings = {}, {}
        for reading in READINGS:
            rubbing = rubbings[reading.name] = frictional_pulls(relaxed, curves, reading, coefficient)
            rows, counts[reading.name] = shell_rows(file, curves, reading, periodic, rubbing, strips)
            print_table(f"{name}: shell and periodic repeat against the largest strip per direction, read as "
                        f"{reading.title} (force within {SHELL_FORCE_RTOL:.0%}, compression within "
                        f"{SHELL_COMPRESSION_ATOL}; % against the strip)",
                        ["direction", "repeats", "level", "swatch N/m", "strain pulled to", "swatch compression",
                         "periodic N/m", "periodic compression", f"periodic with friction μ {coefficient:g} N/m",
                         "its compression", "nonlinear N/m", "nonlinear compression", "linear N/m",
                         "linear compression", "nonlinear strip, same jaws, N/m", "its compression",
                         "its jaws' hold (same jaws / free)", "verdict (nonlinear)", "verdict (its strip)"], rows)
        fitted_to = pulls
        if file.sample_friction > 0.0:
            # A shell fitted to loading paths: its own error is against the frictional pull at the
            # nominal strains (the jaws' reading's, solved above when the friction is the same).
            jaws = READINGS[0]
            fitted_to = (rubbings[jaws.name] if file.sample_friction == coefficient
                         else frictional_pulls(relaxed, curves, jaws, file.sample_friction))
        rows = fit_rows(file, curves, fitted_to)
        if rows:
            kind = (f"with friction μ {file.sample_friction:g}, as its samples" if file.sample_friction > 0.0
                    else "frictionless")
            print_table(f"{name}: nonlinear shell against the periodic repeat's pull ({kind}: the fit's own error; "
                        f"% against the periodic pull)",
                        ["direction", "strain", "periodic N/m", "periodic compression", "periodic converged",
                         "nonlinear N/m", "nonlinear compression"], rows)
        print()
        for reading in READINGS:
            tally = counts[reading.name]
            print(f"shell (nonlinear) pulled free vs largest swatch, {reading.name}: within at {tally.within} of "
                  f"{tally.judged} converged points: {'within' if tally.within == tally.judged else 'MISSED'}")
            print(f"shell (nonlinear) strip between the same jaws vs largest swatch, {reading.name}: within at "
                  f"{tally.strip_within} of {tally.strip_judged} converged points: "
                  f"{'within' if tally.strip_within == tally.strip_judged else 'MISSED'}; "
                  f"where the jaws hold the shell "
                  f"strip within {JAWS_HOLD_RTOL:.0%} of its free pull (a representative test) at "
                  f"{tally.representative_within} of {tally.representative}")
            if tally.rubbed:
                print(f"periodic pull with friction vs largest swatch, {reading.name}: "
                      f"within at {tally.rubbed_within} of {tally.rubbed} converged points")
        unreached = unreached_cells(curves)
        print(f"cells ({', '.join(ACCEPTANCE_DIRECTIONS)} at {', '.join(f'{100 * e:g} %' for e in STRAINS)}) no strip "
              f"here has reached: {', '.join(unreached) if unreached else 'none'}")
        return 0


if __name__ == "__main__":
    sys.exit(main())

"""The ``yarnfit`` command line.

Units at this edge follow textile labels (g/m², threads or stitches per cm, mm, µm); everything
behind it is SI. Errors in the input print one line and exit with status 2 (every output path is
checked writable before any computation); a relaxation that does not converge prints its residuals
and exits with status 1; Ctrl-C stops the work, its workers and queued tasks, writes nothing and
exits with status 130 after one line.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from pathlib import Path

from . import __version__
from .fibers import SPINNING_SYSTEMS
from .checks import error_line
from .outputs import check_writable
from .yarn import YARN_MODELS

EXIT_FAILED = 1
EXIT_USAGE = 2
# What a shell reports for a program ended by SIGINT (128 + 2), so scripts see an interrupt.
EXIT_INTERRUPTED = 130


def split_options(split: dict) -> str:
    """A split (:data:`yarnfit.mujoco.DRAPES_SPLIT`, ``STRIPS_SPLIT``) as `yarnfit export` options."""
    return " ".join(f"--{key.replace('_', '-')} {value}" for key, value in split.items())


class UsageError(Exception):
    """Bad input: printed as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (its default prints the usage first): bad input is always a
    single line on stderr and exit status 2."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="yarnfit",
        description=(
            "Real fabric parameters for MuJoCo cloth: from a fabric's label (fibre, knit or weave, "
            "g/m², threads or stitches per cm) to a fitted orthotropic StVK shell, via a yarn-level "
            "simulation of the fabric's periodic repeat."
        ),
    )
    parser.add_argument("--version", action="version", version=f"yarnfit {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

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

    fit = commands.add_parser(
        "fit",
        help="fit an orthotropic shell to a fabric (relax, homogenize, fit)",
        description=(
            "Relax the fabric's yarn repeat, tile it over sampled stretches, shears and bends (from 0.1 % "
            "and 1 /m up to what the fibre bears), solve each sample at the yarn level (in parallel), fit an "
            "orthotropic shell by least squares: a strain-stiffening membrane (convex ridges in the Green "
            "strain), the linear StVK membrane s00 s01 s11 s22 beside it, and bending "
            "b00 b01 b11 b22; write the material file (JSON, SI units). The summary gives the engineering "
            "constants (small-strain) in N/m and gf·cm²/cm beside SI."
        ),
    )
    fit.add_argument("preset", nargs="?", help="a built-in fabric (see `yarnfit materials`)")
    add_fabric_arguments(fit)
    fit.add_argument("--samples", type=int, default=None, metavar="N",
                     help="about how many deformation samples (at least 45; default 93; a woven, pulled "
                          "along both biases, 9 more)")
    fit.add_argument("--model", choices=("full", "paper"), default="full",
                     help="full: fit b01 too (default); paper: b01 = 0, the paper's 7 parameters")
    fit.add_argument("--strict", action="store_true",
                     help="fail (exit status 1) when the yarn-level energies ask for an indefinite shell, instead of "
                          "fitting the coupling s01 or b01 at the positive-definite bound |rho| = 0.99")
    fit.add_argument("--workers", type=int, default=None, metavar="N",
                     help="processes solving samples (default: every core)")
    add_sample_friction_arguments(fit)
    fit.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                     help="solve the samples on this Dask scheduler's workers instead of local processes")
    fit.add_argument("--name", help="label for the output files (default: preset, pattern or file name)")
    fit.add_argument("-o", "--output", metavar="MATERIAL.json", help="material file (default: <name>.json)")
    fit.add_argument("--rerun", metavar="FILE.rrd", help="Rerun recording of the fit (default: logs/<name>-fit.rrd)")
    fit.add_argument("--figures", metavar="DIR",
                     help="where the fit's figures (PNG, SVG) and their tables (CSV) go (default: logs/<name>)")

    from .mujoco import (DEFAULT_DAMPING, DEFAULT_FRICTION, DEFAULT_INTEGRATOR, DEFAULT_SIZE, DEFAULT_SOLVER,
                         DEFAULT_TIMESTEP, DRAPES_SPLIT, EXPORT_RESOLUTION, EXPORT_SPLIT, IMPLICIT_DRAGS,
                         IMPLICIT_SHARES, INTEGRATORS, MEMBRANES, MESHES, SCENES, SOLVERS, STRIPS_SPLIT)
    from .validate import SCENES as VALIDATION_SCENES

    export = commands.add_parser(
        "export",
        help="write a MuJoCo scene (MJCF) that uses a fitted material",
        description=(
            "Write a MuJoCo scene with a material file's cloth: cloth (hanging from two corners), stretch (a FAB "
            "strip between two clamps, the right one driven by the position actuator 'pull'), sphere (dropped on a "
            "sphere) or wall (dropped across a wall's top edge). The flex carries MuJoCo's built-in isotropic "
            "elasticity (integrated implicitly under the discrete integrator) at least half as stiff as the material "
            "in every direction, which keeps the step stable; the yarnfit.shell plugin removes its forces exactly and "
            "carries the whole material, with the material's strain-stiffening membrane (--linear: the linear StVK "
            "membrane fitted from the same samples). --fallback writes a plugin-free scene with one isotropic "
            "material instead. The file opens with a comment naming the plugin and how to get it, and spells the "
            "cloth out (one body per vertex, every number exact): a <flexcomp> cannot hold its area-lumped vertex "
            "masses. Each scene is written by default with the split `yarnfit validate` runs that kind of scene "
            f"with: the cloth, sphere and wall with the drapes' ({split_options(DRAPES_SPLIT)}; the validated sphere "
            f"at --size 0.3 --resolution 25), the stretch strip with the FAB strips' ({split_options(STRIPS_SPLIT)}). "
            "Lengths in m, times in s."
        ),
    )
    export.add_argument("material", metavar="MATERIAL.json", help="a material file written by `yarnfit fit`")
    export.add_argument("--scene", required=True, choices=SCENES, help="which scene")
    export.add_argument("-o", "--output", metavar="SCENE.xml",
                        help="the scene file (default: <fabric>-<scene>.xml, <fabric>-<scene>-fallback.xml)")
    export.add_argument("--resolution", type=int, metavar="N",
                        help="vertices per side (stretch: along the strip; criss-cross cells add a centre vertex "
                             f"each); default {EXPORT_RESOLUTION['cloth']}, stretch {EXPORT_RESOLUTION['stretch']}")
    export.add_argument("--size", type=float, metavar="M", help="side length in m (stretch: strip length); "
                        f"default {DEFAULT_SIZE['cloth']:g}, stretch {DEFAULT_SIZE['stretch']:g}")
    export.add_argument("--width", type=float, metavar="M", help="strip width in m, stretch only (default 0.05)")
    export.add_argument("--timestep", type=float, default=DEFAULT_TIMESTEP, metavar="S",
                        help=f"time step in s (default {DEFAULT_TIMESTEP:g})")
    export.add_argument("--integrator", default=DEFAULT_INTEGRATOR, choices=list(INTEGRATORS),
                        help=f"MuJoCo integrator (default {DEFAULT_INTEGRATOR}: the built-in part is implicit)")
    scene_solvers = "; ".join(f"{solver} for {', '.join(s for s in SCENES if DEFAULT_SOLVER[s] == solver)}"
                              for solver in SOLVERS)
    export.add_argument("--solver", choices=list(SOLVERS),
                        help=f"MuJoCo's constraint solver (default: the scene's, {scene_solvers}; CG where the cloth "
                             "touches something: twice as fast as Newton on the sphere)")
    export.add_argument("--friction", type=float, default=DEFAULT_FRICTION, metavar="MU",
                        help=f"sliding friction of cloth and obstacles (default {DEFAULT_FRICTION:g})")
    export.add_argument("--damping", type=float, default=DEFAULT_DAMPING, metavar="S",
                        help=f"stiffness-proportional damping time in s (default {DEFAULT_DAMPING:g})")
    export.add_argument("--angle", type=float, default=0.0, metavar="DEG",
                        help="weft direction in degrees from world x (stretch, pulled along x: 0 weft strip, 90 warp, "
                             "-45 bias (the pull at +45° from the weft), 45 the other bias)")
    export.add_argument("--gsm", type=float, metavar="G", help="areal density in g/m² (default: the material file's)")
    export.add_argument("--linear", action="store_true",
                        help="the linear StVK shell fitted from the same samples (quadratic membrane and symmetric bending) "
                             "instead of the strain-stiffening membrane and the signed bending")
    export.add_argument("--fallback", action="store_true",
                        help="no plugin: MuJoCo's built-in isotropic elasticity alone (stretch and bending) with the "
                             "material's isotropic fallback")

    def scene_default(key: str) -> str:
        """The export's default of a split option, per scene (EXPORT_SPLIT), for the help."""
        values = {}
        for scene in SCENES:
            values.setdefault(EXPORT_SPLIT[scene][key], []).append(scene)
        if len(values) == 1:
            return f"{next(iter(values))} for every scene"
        return "; ".join(f"{value} for {', '.join(scenes)}" for value, scenes in values.items())

    export.add_argument("--implicit-drag", choices=IMPLICIT_DRAGS,
                        help="how much of the discrete step's drag through MuJoCo's isotropic share the cloth keeps: "
                             "full or critical (what damps each of the material's modes critically: a quasi-static "
                             f"pull such as the stretch strip comes to rest sooner); default {scene_default('implicit_drag')}")
    export.add_argument("--implicit-share", choices=IMPLICIT_SHARES,
                        help="the membrane MuJoCo integrates implicitly: isotropic (its <elasticity>, stiff enough for "
                             "the material's stiffest direction in every direction, which drags the soft modes) or "
                             "anisotropic (half the material's tangent in each mode, written by the plugin over "
                             "MuJoCo's metric: a woven's shear is no longer held back, and lightly damped modes swing "
                             f"longer); default {scene_default('implicit_share')}")
    export.add_argument("--mesh", choices=list(MESHES),
                        help="the cloth's cells: grid (one diagonal per cell) or crisscross (both diagonals around a "
                             "centre vertex: twice the vertices at the same --resolution, no locking with triangle "
                             f"strains); default {scene_default('mesh')}")
    export.add_argument("--membrane", choices=list(MEMBRANES),
                        help="the plugin's membrane strains: node (smoothed over each vertex's triangles, no locking "
                             "on any mesh) or triangle (constant per triangle: locks on one-diagonal cells, use it "
                             f"with --mesh crisscross); default {scene_default('membrane')}")
    export.add_argument("--self-collision", action="store_true", help="let the cloth collide with itself (slower)")
    export.add_argument("--check", type=float, metavar="SECONDS",
                        help="then step the scene this long and report stability and ms/step (exit 1 if unstable)")
    catalogue = commands.add_parser(
        "catalogue",
        help="fit, export and validate every fabric of a labels table (CSV), locally or on a Dask cluster",
        description=(
            "Fit, export and (with --validate) validate every row of a CSV labels table: a header row "
            "name,fibre,pattern,gsm,counts (gsm in g/m², counts per cm as 18x13, empty for the pattern's typical "
            "counts) and optional yarn_model, yarn_spinning, yarn_packing, yarn_twist_deg columns; one fabric per "
            "row. Writes DIR/<name>.json, DIR/<name>-cloth.xml and one table, DIR/catalogue.csv and "
            "DIR/catalogue.parquet, of inputs, engineering constants, fit quality and verdicts. The work runs as "
            "tasks on local worker processes, a local Dask cluster (--dask) or an existing Dask scheduler "
            "(--scheduler); results are cached in DIR/.cache, so a rerun or an interrupted run resumes without "
            "recomputing. A failing row gets its one-line reason in the table; the others still complete."
        ),
    )
    catalogue.add_argument("labels", metavar="LABELS.csv", help="the labels table")
    catalogue.add_argument("-o", "--output", required=True, metavar="DIR", help="where the results go")
    catalogue.add_argument("--samples", type=int, default=None, metavar="N",
                           help="about how many deformation samples per fabric (at least 45; default 93; a "
                                "woven, pulled along both biases, 9 more)")
    catalogue.add_argument("--model", choices=("full", "paper"), default="full", help="as for `yarnfit fit`")
    add_sample_friction_arguments(catalogue)
    catalogue.add_argument("--validate", action="store_true",
                           help="also run the validation scenes (quick: stretch, sphere, cusick) on each fabric")
    catalogue.add_argument("--workers", type=int, default=None, metavar="N",
                           help="local worker processes (default: every core)")
    catalogue.add_argument("--dask", action="store_true", help="run on a local dask.distributed cluster")
    catalogue.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="run on this Dask scheduler's workers")

    show = commands.add_parser(
        "show", help="open a material's or a validation's figures, a scene in MuJoCo's viewer, or a recording in Rerun",
        description=(
            "Open FILE by its kind: a material file (yarnfit fit) or a validation summary.json (yarnfit validate): "
            "its figures, drawn into --figures (default: beside the file) and shown in a window; a scene (.xml): "
            "MuJoCo's viewer; a recording (.rrd): the Rerun viewer. Without a display the figures' paths are printed."
        ),
    )
    show.add_argument("file", metavar="FILE", help="MATERIAL.json, summary.json, SCENE.xml or RECORDING.rrd")
    show.add_argument("--figures", metavar="DIR", help="where the figures are drawn (default: beside FILE)")

    validate = commands.add_parser(
        "validate",
        help="run the validation suite on a fitted material (stretch tests, drapes, Cusick test, yarn swatch, body)",
        description=(
            "Run the validation scenes on a material file: stretch (FAB strips 8x5 and 2x5 cm along weft, warp "
            "and bias in MuJoCo), yarn (the same pull on an explicit yarn swatch), sphere and wall (drapes), "
            "cusick (the Cusick drape test, BS 5058 / ISO 9073-9), body (garments on a moving humanoid). Each "
            "scene is recorded to <logs>/<fabric>/<scene>.rrd and every figure goes to "
            "<logs>/<fabric>/summary.json, in SI units."
        ),
    )
    validate.add_argument("material", metavar="MATERIAL.json", help="a material file written by `yarnfit fit`")
    validate.add_argument("--scenes", default=",".join(VALIDATION_SCENES), metavar="LIST",
                          help=f"comma-separated scenes (default: {','.join(VALIDATION_SCENES)})")
    validate.add_argument("--quick", action="store_true", help="coarse meshes and short runs (for CI)")
    validate.add_argument("--reference", metavar="CURVES.csv",
                          help="measured stretch curves to compare with (CSV with units in the header; see README)")
    validate.add_argument("--logs", default="logs", metavar="DIR", help="where recordings and summary.json go")
    validate.add_argument("--strict", action="store_true",
                          help="exit 1 when a check misses its criterion (each is printed as pass, FAIL or n/a)")
    validate.add_argument("--workers", type=int, default=None, metavar="N",
                          help="run the scenes side by side on N worker processes (default: one per core; "
                               "1 runs them one after another in this process)")
    return parser


def add_sample_friction_arguments(parser: argparse.ArgumentParser) -> None:
    """``--friction`` / ``--frictionless``: how the membrane samples are solved (``args.friction``:
    True, False, or None for the structure's default, :func:`yarnfit.fabric_fit.loads_with_friction`)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--friction", action="store_true", default=None,
                       help="load the membrane samples from rest with the fibre's friction (the fabric's loading "
                            "response, as a tensile test measures it; every sample family a path of 0.5 %% steps, "
                            "about 3 times slower): the default for knits")
    group.add_argument("--frictionless", dest="friction", action="store_false", default=None,
                       help="solve the membrane samples as the paper's frictionless minimisers: the default for "
                            "wovens")


def add_fabric_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fiber", help="fibre name (see `yarnfit materials`)")
    parser.add_argument("--fiber-file", metavar="FIBER.json",
                        help="a fibre of your own as JSON (keys: name, density_kg_m3, young_min_pa, young_max_pa, "
                             "breaking_strain, poisson, friction; for the fibre-assembly yarn also fineness_dtex "
                             "or diameter_m, flexural_rigidity_nm2_per_tex2, torsional_rigidity_nm2_per_tex2)")
    parser.add_argument("--pattern", help="named weave or knit (see `yarnfit patterns`)")
    parser.add_argument("--pattern-file", metavar="FILE.pyp", help="a periodic yarn pattern in the .pyp format")
    parser.add_argument("--gsm", type=float, metavar="G", help="areal density in g/m²")
    parser.add_argument("--counts", metavar="AxB",
                        help="per cm: ends x picks for wovens, courses x wales for knits (e.g. 30x25)")
    parser.add_argument("--yarn-model", choices=YARN_MODELS, default=None,
                        help="fibre-assembly (default: a bundle of sliding fibres, bending and twisting near the sum "
                             "of the fibres') or solid (the paper's solid rod of fibre material)")
    parser.add_argument("--yarn-spinning", choices=SPINNING_SYSTEMS, default=None,
                        help="how the yarn is spun (default: the fibre's usual system, see `yarnfit materials`)")
    parser.add_argument("--yarn-packing", type=float, metavar="PHI",
                        help="packing fraction of fibres in the yarn, in (0, 1] (default: the spinning system's)")
    parser.add_argument("--yarn-twist-deg", type=float, metavar="DEG",
                        help="surface twist angle of the yarn in degrees, in [0, 45) (default: the spinning system's)")
    parser.add_argument("--yarn", metavar="YARN.json", dest="yarn_file",
                        help="the yarn's construction as JSON (keys: model, spinning, packing_fraction, "
                             "twist_angle_deg, and measured tensile_rigidity_n, bending_rigidity_nm2, "
                             "torsional_rigidity_nm2 of a single yarn, SI units)")


def fabric_from_arguments(args: argparse.Namespace):
    """The :class:`~yarnfit.fabric.Fabric` an argument namespace describes (UsageError if it
    describes none)."""
    from .fabric import Fabric
    from .fibers import get_fiber, load_fiber_file

    counts = parse_counts(args.counts) if args.counts is not None else None
    if args.gsm is not None and not (math.isfinite(args.gsm) and args.gsm > 0):
        raise UsageError(f"--gsm must be a positive areal density in g/m², got {args.gsm:g}")
    yarn = yarn_from_arguments(args)
    if args.preset is not None:
        if any(v is not None for v in (args.fiber, args.fiber_file, args.pattern, args.pattern_file, args.gsm, args.counts)):
            raise UsageError("a preset fixes the fabric: give either a preset or --fiber/--pattern/--gsm/--counts")
        fabric = Fabric.preset(args.preset, yarn=yarn)
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
        yarn=yarn,
    )


def yarn_from_arguments(args: argparse.Namespace):
    """The :class:`~yarnfit.yarn.YarnConstruction` of ``--yarn FILE`` or the ``--yarn-*`` options
    (UsageError if both are given)."""
    from .yarn import YarnConstruction, load_yarn_file

    options = {"model": args.yarn_model, "spinning": args.yarn_spinning, "packing_fraction": args.yarn_packing,
               "twist_angle_deg": args.yarn_twist_deg}
    given = {key: value for key, value in options.items() if value is not None}
    if args.yarn_file is not None:
        if given:
            raise UsageError("give the yarn either as --yarn FILE or with --yarn-model/--yarn-spinning/--yarn-packing/"
                             "--yarn-twist-deg, not both")
        return load_yarn_file(args.yarn_file)
    try:
        return YarnConstruction(**given)
    except ValueError as exc:
        raise UsageError(f"yarn: {exc}") from None


def parse_counts(text: str) -> tuple[float, float]:
    """``"AxB"`` per cm → ``(A, B)`` per metre."""
    from .fabric import counts_from_label

    try:
        return counts_from_label(text)
    except ValueError as error:
        raise UsageError(f"--{error}") from None


def _renamed(fabric, name: str):
    from dataclasses import replace

    return replace(fabric, name=name)


@contextlib.contextmanager
def announce_compilation(line: "ProgressLine"):
    """Say "compiling kernels (first run only)" on ``line`` when Numba first compiles a kernel
    inside the block: the kernels are cached on disk (``cache=True``), so only a first run (or one
    after an upgrade) compiles, for about 25 s, and would otherwise sit silent. Numba's event API
    reports compilations, not cache loads."""
    from numba.core import event

    class Listener(event.Listener):
        said = False

        def on_start(self, ev):
            if not self.said:
                self.said = True
                line.message("compiling kernels (first run only)", force=True)

        def on_end(self, ev):
            pass

    with event.install_listener("numba:compile", Listener()):
        yield


# -- commands ---------------------------------------------------------------------------------


def cmd_materials(args: argparse.Namespace) -> int:
    from .fabric import PRESETS
    from .fibers import FIBERS
    from .yarn import SPINNING_DEFAULTS

    print("fibres:")
    for fiber in FIBERS.values():
        print("  " + fiber.describe())
    print("yarn construction defaults (--yarn-spinning, --yarn-packing, --yarn-twist-deg):")
    for name, spinning in SPINNING_DEFAULTS.items():
        print(f"  {name:<10} φ {spinning.packing_fraction:.2f}  twist {spinning.twist_angle_deg:4.1f}°  ({spinning.source})")
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

    def message(self, text: str, force: bool = False) -> None:
        """Show ``text`` (off a terminal: only every few seconds, unless ``force``)."""
        self._write(text, force)

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
    path = check_writable(Path(args.rerun) if args.rerun else Path("logs") / f"{fabric.name}.rrd", "--rerun recording")
    if args.output:
        check_writable(args.output, "relaxed pattern")
    recording = None  # opened once the fabric has given a valid pattern: bad input writes no file
    line = ProgressLine()

    def on_start(pattern):
        nonlocal recording
        if recording is None:
            recording = RelaxRecording(fabric.name, path)
        recording.start(pattern)
        line.start_relaxation(pattern)

    def on_iteration(p):
        recording(p)
        line(p)

    result = relax(fabric, on_iteration=on_iteration, on_start=on_start)
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


def sample_progress(done: int, total: int, result) -> str:
    """The fit's progress line for its ``done``-th of ``total`` samples, a
    :class:`~yarnfit.samples.SampleResult`: its energy, or that it was excluded. An unconverged
    sample's energy is where its solve stopped (cotton jersey's jammed compression: 2e6 J/m²), not a
    figure of the fabric, so it is not printed."""
    outcome = f"{result.energy_density:.3g} J/m²" if result.converged else "did not converge: excluded from the fit"
    return f"samples {done}/{total}: {result.spec.family} {result.spec.parameter:+.3g} → {outcome}"


def cmd_fit(args: argparse.Namespace) -> int:
    from .fit import COUPLING_LIMIT
    from .samples import design_size
    from .fabric_fit import DEFAULT_SAMPLES, fit_fabric
    from .record import FitRecording
    from .tasks import make_backend

    fabric = fabric_from_arguments(args)
    samples = DEFAULT_SAMPLES if args.samples is None else args.samples
    if samples < design_size(1):
        raise UsageError(f"--samples must be at least {design_size(1)} (one per sample family and sign), "
                         f"got {samples}")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
    output = check_writable(Path(args.output) if args.output else Path(f"{fabric.name}.json"), "material file")
    path = check_writable(Path(args.rerun) if args.rerun else Path("logs") / f"{fabric.name}-fit.rrd",
                          "--rerun recording")
    figures = check_writable(Path(args.figures) if args.figures else Path("logs") / fabric.name, "--figures directory",
                             directory=True)
    line = ProgressLine()
    sampling_started = [0.0]

    def on_relaxed(relaxed):
        sampling_started[0] = time.perf_counter()
        line.message(f"relaxed in {relaxed.seconds:.1f} s (radius {relaxed.radius * 1e6:.2f} µm); solving samples",
                     force=True)

    def on_sample(done, total, result):
        now = time.perf_counter()
        left = (now - sampling_started[0]) / done * (total - done)
        line.message(f"{sample_progress(done, total, result)}  [{now - line.start:.0f} s, ~{left:.0f} s left]",
                     force=not result.converged or done == total)

    line.message(f"{fabric.name}: relaxing the repeat", force=True)
    with make_backend(args.scheduler, args.workers) as backend, announce_compilation(line):
        fitted = fit_fabric(fabric, samples=samples, model=args.model, on_relaxed=on_relaxed, on_sample=on_sample,
                            on_relax_iteration=line, on_relax_start=line.start_relaxation,
                            coupling_limit=None if args.strict else COUPLING_LIMIT, backend=backend,
                            friction=args.friction)
    line.close()
    fitted.write(output)
    recording = FitRecording(fabric.name, path)
    recording.start(fitted.relaxed)
    for index, result in enumerate(fitted.samples):
        recording.sample(index, fitted.relaxed, result)
    recording.finish(fitted)
    print(fit_summary(fitted, output, path))
    from .plots import fit_figures

    try:
        drawn = fit_figures(output, figures)
    except ValueError as error:  # the material file is written: a figure that cannot be drawn says why
        print(f"yarnfit fit: figures not drawn: {error_line(error)}", file=sys.stderr)
        return 0
    print(f"figures: {len(drawn)} files in {figures} (PNG, SVG, CSV; `yarnfit show {output}` opens them)")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from .mujoco.scenes import ClothMaterial, export_options, export_scene

    if args.resolution is not None and args.resolution < 2:
        raise UsageError(f"--resolution must be at least 2 vertices per side, got {args.resolution}")
    for option, value in (("--size", args.size), ("--width", args.width), ("--timestep", args.timestep),
                          ("--gsm", args.gsm), ("--check", args.check)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise UsageError(f"{option} must be positive, got {value:g}")
    for option, value in (("--friction", args.friction), ("--damping", args.damping)):
        if not (math.isfinite(value) and value >= 0):
            raise UsageError(f"{option} must be zero or positive, got {value:g}")
    if not math.isfinite(args.angle):
        raise UsageError(f"--angle must be a finite number of degrees, got {args.angle:g}")
    if args.width is not None and args.scene != "stretch":
        raise UsageError("--width is the stretch strip's width: give it with --scene stretch only")
    material = ClothMaterial.from_file(args.material, None if args.gsm is None else args.gsm * 1e-3,
                                       linear=args.linear)
    suffix = "-fallback" if args.fallback else ""
    output = check_writable(Path(args.output) if args.output else Path(f"{material.name}-{args.scene}{suffix}.xml"),
                            "scene file")
    strip = {} if args.width is None else {"width": args.width}
    scene_options = export_options(args.scene, resolution=args.resolution, implicit_drag=args.implicit_drag,
                           implicit_share=args.implicit_share, mesh=args.mesh, membrane=args.membrane)
    built = export_scene(material, args.scene, output, size=args.size, **strip, **scene_options,
                         timestep=args.timestep, integrator=args.integrator, solver=args.solver,
                         friction=args.friction,
                         damping=args.damping, angle=math.radians(args.angle), fallback=args.fallback,
                         self_collision=args.self_collision)
    print(export_summary(built, material, output, args, scene_options))
    if args.check is not None:
        from .mujoco.run import run_scene

        report = run_scene(output, args.check)
        print(f"  check           {report}")
        if not report.stable:
            print(f"yarnfit export: the scene became unstable after {report.simulated_s:.3g} s: try a smaller "
                  "--timestep or --integrator discrete", file=sys.stderr)
            return EXIT_FAILED
    return 0


def export_summary(built, material, output, args, scene_options: dict) -> str:
    """What `yarnfit export` wrote: ``scene_options`` the scene's options as built (export_options:
    its split and resolution)."""
    from .mujoco.scenes import SOLVER_LABEL

    spec = built.spec
    lines = [f"{material.name}: {built.scene} scene{' (isotropic fallback, no plugin)' if built.fallback else ''}, "
             f"{spec.flexes[0].name} flex of {len(spec.flexes[0].vertbody)} vertices, "
             f"{material.areal_density_kg_m2 * 1e3:.4g} g/m², {args.integrator} Δt = {args.timestep:g} s, "
             f"{SOLVER_LABEL[spec.option.solver]} solver"]
    if built.fallback:
        part = "elastic2d both: stretch and bending"
    elif scene_options["implicit_share"] == "anisotropic":
        part = ("its bending share implicit under discrete; its membrane metric rewritten by the plugin with the "
                "anisotropic share, half the material's tangent in each mode")
    elif spec.flexes[0].elastic2d == 3:
        part = "elastic2d both: isotropic stretch and bending shares, implicit under discrete"
    else:
        part = "elastic2d stretch: implicit under discrete"
    lines.append(f"  built-in        E = {built.young_pa:.6g} Pa, ν = {built.poisson:.6g}, "
                 f"h = {built.thickness_m * 1e3:.4g} mm ({part})")
    if not built.fallback:
        membrane = ("strain-stiffening membrane" if material.shell.nonlinear is not None
                    else "linear membrane (--linear)" if args.linear else "linear membrane")
        # --linear: the symmetric (quadratic) bending of the same fit.
        kind = "signed " if material.shell.signed_bending is not None else "symmetric " if args.linear else ""
        bending = (f"its own {kind}bending, the built-in hinge forces removed" if spec.flexes[0].elastic2d == 3
                   else f"all {kind}bending")
        lines.append(f"  plugin          yarnfit.shell: the full material (orthotropic rest, {membrane}, "
                     f"{bending}), weft at {args.angle:g}° from x, {scene_options['membrane']} membrane strains on "
                     f"{scene_options['mesh']} cells, implicit_drag {scene_options['implicit_drag']}, "
                     f"implicit_share {scene_options['implicit_share']}")
    if not built.fallback and material.shell.nonlinear is not None and args.check is None:
        lines.append("  note            the strain-stiffening forces are explicit and can need a step below 1 ms "
                     "(plugins/README.md): check the scene with --check SECONDS, or export --linear")
    lines += [f"  note            {note}" for note in built.notes]
    lines.append(f"  scene           {output}")
    return "\n".join(lines)


def short_sample_notes(samples) -> list[str]:
    """One sentence per sample taken short of the design's parameter
    (:attr:`~yarnfit.samples.SampleResult.design_parameter`): where and why."""
    return [f"{s.family} sampled at {s.parameter:+.3g} for the design's {s.design_parameter:+.3g}: its loading "
            f"path converged no further (the fabric does not bear more)"
            for s in samples if math.isfinite(s.design_parameter)]


def fit_summary(fitted, output, recording_path) -> str:
    from .shell import GF_CM2_PER_CM

    fabric, relaxed, fit = fitted.fabric, fitted.relaxed, fitted.fit
    eng = fitted.material.engineering()
    used, excluded = len(fit.used), len(fit.excluded)
    label = f"{fabric.areal_density * 1e3:.4g} g/m²" if fabric.areal_density else "as written"
    lines = [
        f"{fabric.name}: {fabric.fiber.name}, {relaxed.pattern.family} "
        f"{fabric.structure or Path(str(fabric.pattern_file)).name}, {label}; {fit.model} model, "
        f"{_plural(used, 'sample')} fitted" + (f", {excluded} excluded (did not converge)" if excluded else ""),
        *(f"  {text}" for text in relaxed.yarn.describe()),
        f"  {'weft stretch':<16}{eng['weft_stretch_n_per_m']:12.5g} N/m",
        f"  {'warp stretch':<16}{eng['warp_stretch_n_per_m']:12.5g} N/m",
        f"  {'poisson weft':<16}{eng['poisson_weft']:12.4g}",
        f"  {'poisson warp':<16}{eng['poisson_warp']:12.4g}",
        f"  {'shear':<16}{eng['shear_n_per_m']:12.5g} N/m",
    ]
    for key, label in (("bending_weft_nm", "bending weft"), ("bending_warp_nm", "bending warp"),
                       ("bending_bias_nm", "bending bias")):
        lines.append(f"  {label:<16}{eng[key]:12.5g} N·m   {eng[key] / GF_CM2_PER_CM:10.4g} gf·cm²/cm")
    signed = fitted.material.signed_bending
    if signed is not None:  # the symmetric figures above are the fit beside it (--linear's)
        h3 = fitted.material.thickness**3
        for label, positive, negative in (("signed weft", signed.b00_pos, signed.b00_neg),
                                          ("signed warp", signed.b11_pos, signed.b11_neg)):
            lines.append(f"  {label:<16}{h3 * positive:12.5g} / {h3 * negative:.5g} N·m towards / away from +z "
                         f"(the material's bending; the figures above: symmetric)")
    lines.append(f"  {'thickness':<16}{fitted.material.thickness * 1e3:12.4g} mm")
    # R² needs spread within a family; a family of one sample gets its relative RMS error instead.
    quality = ", ".join(f"{family} {q['r2']:.3f}" if q["samples"] > 1 else f"{family} (rms {q['relative_rms']:.2g})"
                        for family, q in fit.families.items())
    lines.append(f"  fit R²          {quality}")
    if fit.membrane == "nonlinear" or fit.bending == "signed":
        shown = (("weft_s", "warp_s", "biaxial", "shear") if fit.membrane == "nonlinear" else ()) + (
            ("weft_bend", "warp_bend", "bias_bend", "saddle_bend") if fit.bending == "signed" else ())
        linear_quality = ", ".join(f"{family} {q['r2']:.3f}" for family, q in fit.linear_families.items()
                                   if family.startswith(shown))
        # The linear membrane is fitted to tension alone (even in the strain's sign, fit.fit_shell).
        over = " (membrane: over tension)" if fit.membrane == "nonlinear" else ""
        lines.append(f"  linear R²       {linear_quality}{over}")
    if fit.membrane == "nonlinear":
        lines.append(f"  stiffening      {_stiffening_summary(fit)}")
    lines.append(f"  pulled          {_pull_summary(fitted.material)}")
    if fit.reference_energy or any(fit.residual_stress.values()):
        r = fit.residual_stress
        stress = (f"residual stress {r['n0']:.3g} / {r['n1']:.3g} N/m weft / warp (fitted), "
                  if any(r[n] for n in ("n0", "n1", "n2")) else "")
        lines.append(f"  rest state      {stress}moments {r['m0']:.3g} / {r['m1']:.3g} N (from ±κ), rest energy "
                     f"{fit.reference_energy:.3g} J/m² (bends, at zero membrane force: {fit.bending_reference:.3g}): "
                     f"left out of the shell")
    lines += [f"  note            {note}" for note in fit.notes]
    lines += [f"  note            {note}" for note in short_sample_notes(fitted.samples)]
    lines.append("  samples         " + (f"membrane loaded from rest with friction μ {fitted.sample_friction:g} "
                                         "(--frictionless: the paper's minimisers); bends frictionless"
                                         if fitted.sample_friction > 0.0 else
                                         "frictionless minimisers (the paper's; --friction loads them)"))
    t = fitted.seconds
    lines.append(f"  time            relax {t['relax']:.1f} s, samples {t['homogenize']:.1f} s, fit {t['fit']:.2f} s "
                 f"(total {sum(t.values()):.1f} s)")
    lines.append(f"  material        {output}")
    lines.append(f"  recording       {recording_path}")
    return "\n".join(lines)


def relax_summary(result, fabric, recording_path, output) -> str:
    px, py = result.repeat_size
    lines = [
        f"{result.name}: {fabric.fiber.name}, {result.pattern.family}, {_plural(len(result.pattern.yarns()), 'yarn')}, "
        f"{result.model.n_nodes} nodes",
        f"  repeat            {px * 1e3:.4g} mm × {py * 1e3:.4g} mm",
        f"  yarn radius       {result.radius * 1e6:.4g} µm",
        *(f"  {text}" for text in result.yarn.describe()),
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


# The strains of the fit summary's pulls: the stretch test's 2 and 5 %.
SUMMARY_PULL_STRAINS = (0.02, 0.05)


def _pull_summary(material) -> str:
    """The material's own uniaxial pull (every other stress free) along weft, warp and both
    biases at :data:`SUMMARY_PULL_STRAINS`, N/m: where a woven's twill line shows (its two biases
    apart) and the stiffening past the small-strain constants above."""
    import math

    from .validate import PULL_DIRECTIONS

    strains = " / ".join(f"{100 * e:g}" for e in SUMMARY_PULL_STRAINS)
    parts = []
    for direction, degrees in PULL_DIRECTIONS.items():
        forces = []
        for strain in SUMMARY_PULL_STRAINS:
            try:
                forces.append(f"{material.uniaxial_pull(math.radians(degrees), 1.0 + strain).force_n_per_m:.4g}")
            except ValueError:  # no free width balances the pull there (a StVK width collapsing)
                forces.append("-")
        parts.append(f"{direction} ({degrees:g}°) {' / '.join(forces)}")
    return f"{', '.join(parts)} N/m at {strains} % (width free)"


def _stiffening_summary(fit) -> str:
    """Tangent stiffness at the largest sampled strain over the small-strain one, per direction
    (the pure stretch or shear: the other strains held)."""
    import numpy as np

    from .shell import SMALL_STRAIN

    material = fit.material
    if material.nonlinear is None:
        return "none (its fit failed: see the notes)"
    parts = []
    for k, (direction, label) in enumerate((("s00", "weft"), ("s11", "warp"), ("s22", "shear"))):
        top = fit.strain_range.get(direction, [0.0, 0.0])[1]
        eps = np.zeros(3)
        eps[k] = SMALL_STRAIN
        small = float(material.nonlinear.hessian(eps)[k, k])
        eps[k] = top
        tangent = float(material.nonlinear.hessian(eps)[k, k])
        parts.append(f"{label} ×{tangent / small:.3g} at {100 * top:.3g} %" if small > 0.0
                     else f"{label} {tangent:.3g} Pa at {100 * top:.3g} % (0 at small strain)")
    return ", ".join(parts)


def _plural(count: int, noun: str) -> str:
    return f"{count} {noun}{'' if count == 1 else 's'}"


def cmd_validate(args: argparse.Namespace) -> int:
    from .validate import SCENES as VALIDATION_SCENES
    from .validate.reference import read_reference
    from .tasks import LocalPool
    from .validate.suite import run_suite
    from .validate.verdicts import Verdict

    scenes = [scene.strip() for scene in args.scenes.split(",") if scene.strip()]
    unknown = [scene for scene in scenes if scene not in VALIDATION_SCENES]
    if unknown or not scenes:
        raise UsageError(f"--scenes: unknown scene {', '.join(unknown) or '(none given)'}; "
                         f"scenes: {', '.join(VALIDATION_SCENES)}")
    reference = read_reference(args.reference) if args.reference else None
    check_writable(args.logs, "--logs directory", directory=True)

    def progress(message: str) -> None:
        print(f"  {message}", file=sys.stderr, flush=True)

    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
    with LocalPool(args.workers, tasks=len(scenes)) as backend:
        summary, path = run_suite(args.material, scenes, quick=args.quick, logs=args.logs, reference=reference,
                                  progress=progress, backend=backend)
    print(f"validated {summary['material']['name']}: {path}")
    if {"stretch", "yarn"} & set(summary.get("scenes", {})):  # the scenes with curves to draw
        from .plots import validation_figures

        try:
            drawn = validation_figures(summary, path.parent, reference, material=args.material)
            print(f"  figures: {len(drawn)} files in {path.parent} (`yarnfit show {path}` opens them)")
        except ValueError as error:  # summary.json is written: say why the figures are not
            print(f"yarnfit validate: figures not drawn: {error_line(error)}", file=sys.stderr)
    for scene, seconds in summary["wall_seconds"].items():
        recording = path.parent / (scene + ".rrd") if scene in summary["scenes"] else ""
        print(f"  {scene:<8} {seconds:7.1f} s  {recording}")
    results = [Verdict(**v) for v in summary["verdicts"]]
    for verdict in results:
        print(f"  {verdict.line()}")
    failed = [v.check for v in results if v.passed is False]
    if failed and args.strict:
        print(f"yarnfit validate: failed: {', '.join(failed)}", file=sys.stderr)
        return EXIT_FAILED
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    from .jsonfile import read_json

    path = Path(args.file)
    if not path.is_file():
        raise UsageError(f"{path}: no such file")
    kind = path.suffix.lower()
    if kind == ".rrd":
        return _view_recording(path)
    if kind in (".xml", ".mjcf"):
        return _view_scene(path)
    if kind != ".json":
        raise UsageError(f"{path}: cannot show a {kind or 'file without an extension'} file "
                         "(a material .json, a summary.json, a scene .xml or a recording .rrd)")
    _, data = read_json(path, "file")
    if not isinstance(data, dict) or not ("shell" in data or "verdicts" in data):
        raise UsageError(f"{path}: neither a material file (no 'shell') nor a validation summary (no 'verdicts')")
    folder = check_writable(Path(args.figures) if args.figures else path.parent, "--figures directory", directory=True)
    from .plots import fit_figures, validation_figures

    if "shell" in data:
        drawn = fit_figures(path, folder)
    else:
        material = data.get("material", {}).get("file")
        drawn = validation_figures(path, folder, material=material if material and Path(material).is_file() else None)
    return _open_figures([p for p in drawn if p.suffix == ".png"])


def _open_figures(paths: list[Path]) -> int:
    """Show the PNG ``paths`` in matplotlib windows (one per figure, closed together), or without a
    display print them."""
    import matplotlib

    if matplotlib.get_backend().lower() in ("agg", "svg", "pdf", "ps", "cairo", "template") or not _has_display():
        print("no display: the figures are")
        for p in paths:
            print(f"  {p}")
        return 0
    import matplotlib.image as image
    import matplotlib.pyplot as plt

    for p in paths:
        figure = plt.figure(p.stem)
        axes = figure.add_axes((0, 0, 1, 1))
        axes.imshow(image.imread(p))
        axes.set_axis_off()
    plt.show()
    return 0


def _view_scene(path: Path) -> int:
    """MuJoCo's interactive viewer on the scene (blocks until its window closes)."""
    if not _has_display():
        raise UsageError("no display for MuJoCo's viewer (DISPLAY and WAYLAND_DISPLAY are unset)")
    import mujoco.viewer

    mujoco.viewer.launch_from_path(str(path))
    return 0


def _view_recording(path: Path) -> int:
    """The Rerun viewer on the recording (rerun-sdk's own `rerun` command)."""
    import subprocess

    return subprocess.run([sys.executable, "-m", "rerun", str(path)]).returncode


def _has_display() -> bool:
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def cmd_catalogue(args: argparse.Namespace) -> int:
    from .catalogue import read_labels, run_catalogue
    from .fabric_fit import DEFAULT_SAMPLES
    from .samples import design_size
    from .tasks import SkippedTask, make_backend

    samples = DEFAULT_SAMPLES if args.samples is None else args.samples
    if samples < design_size(1):
        raise UsageError(f"--samples must be at least {design_size(1)}, got {samples}")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
    read_labels(args.labels)  # a file that cannot be read fails before any worker starts
    out = check_writable(args.output, "catalogue directory", directory=True)
    line = ProgressLine()
    failures = [0]

    def on_done(task, outcome, done, total):
        if isinstance(outcome, BaseException) and not isinstance(outcome, SkippedTask) \
                and task.key[0] in ("relax", "fit", "export", "validate"):
            failures[0] += 1
            line.message(f"{task.describe()}: failed: {error_line(outcome)}", force=True)
        width = 30
        bar = "#" * round(width * done / total) + "." * (width - round(width * done / total))
        line.message(f"[{bar}] {done}/{total} tasks, {failures[0]} failed  [{time.perf_counter() - line.start:.0f} s] "
                     f"{task.describe()}", force=done == total)

    with make_backend(args.scheduler, args.workers, dask=args.dask) as backend, announce_compilation(line):
        run = run_catalogue(args.labels, out, backend, samples=samples, model=args.model, validate=args.validate,
                            on_done=on_done, friction=args.friction)
    line.close()
    width = max(len(e.label.name) for e in run.entries)
    for entry in run.entries:
        if entry.status == "ok":
            e = entry.engineering
            verdicts = "" if entry.verdicts_passed is None else \
                f", checks passed {entry.verdicts_passed}" + (f", missed: {', '.join(entry.verdicts_failed)}"
                                                              if entry.verdicts_failed else "")
            print(f"  {entry.label.name:<{width}}  ok      weft {e.get('weft_stretch_n_per_m', math.nan):7.4g} N/m, "
                  f"warp {e.get('warp_stretch_n_per_m', math.nan):7.4g} N/m, fit error ≤ {100 * entry.fit_max_relative_rms:.2g} % "
                  f"({entry.fit_worst_family}){verdicts}")
        else:
            print(f"  {entry.label.name or '(line ' + str(entry.label.line) + ')':<{width}}  FAILED  "
                  f"{entry.stage}: {entry.reason}")
    print(f"catalogue: {len(run.entries) - len(run.failed)} of {len(run.entries)} fabrics ok; {run.table_csv}, "
          f"{run.table_parquet}")
    return EXIT_FAILED if run.failed else 0


COMMANDS = {"materials": cmd_materials, "patterns": cmd_patterns, "relax": cmd_relax, "fit": cmd_fit,
            "export": cmd_export, "validate": cmd_validate, "catalogue": cmd_catalogue, "show": cmd_show}


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    from .fit import IndefiniteFitError
    from .fabric_fit import UnusableRelaxation
    from .patterns import PatternError

    try:
        return COMMANDS[args.command](args)
    except KeyboardInterrupt:
        # The work has been stopped where it ran (yarnfit.tasks); outputs are written whole at the
        # end or not at all, and recordings streamed so far are deleted.
        if "yarnfit.record" in sys.modules:
            sys.modules["yarnfit.record"].Recording.discard_open()
        print(f"\nyarnfit {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (IndefiniteFitError, UnusableRelaxation) as error:
        # The input was fine; the computation did not give a usable result.
        print(f"yarnfit {args.command}: failed: {error_line(error)}", file=sys.stderr)
        return EXIT_FAILED
    except (UsageError, PatternError, ValueError, OSError) as error:
        print(f"yarnfit {args.command}: error: {error_line(error)}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())

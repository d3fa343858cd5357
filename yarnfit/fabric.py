"""Fabric descriptions: what a label and a magnifying glass tell, turned into a yarn pattern.

A :class:`Fabric` names a fibre, a structure (a named weave or knit, or a ``.pyp`` file), the
areal density and the thread or stitch counts. :meth:`Fabric.pattern` builds the periodic repeat
with the yarn radius of the paper's formula (§4.1)::

    r = sqrt(ρ_fabric p_x p_y / (ρ_yarn L0 π))

``ρ_fabric`` the areal density (kg/m²), ``p_x p_y`` the repeat, ``L0`` the yarn length in it and
``ρ_yarn = φ ρ_fibre`` the yarn's density (:meth:`yarnfit.yarn.YarnConstruction.yarn_density`: φ the
packing fraction, 1 for the paper's solid yarn, whose radius is that of the fibre mass). The generated
geometry depends on r (crimp and loop depth scale with it), so r is the fixed point of that
formula over the geometry; relaxation (:mod:`yarnfit.relax`) repeats the fixed point on the relaxed
length, so the relaxed repeat carries the stated areal density.

Counts are per metre inside (per cm at the command line): ``(ends, picks)`` for wovens — ends
(warp yarns, along y) counted across x, picks (weft, along x) counted along y — and
``(courses, wales)`` for knits — courses (each one a yarn along x) counted along y, wales across x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .fibers import Fiber, get_fiber
from .patterns import DRAFTS, STITCHES, PatternError, YarnPattern, knit, read_pyp, weave
from .yarn import YarnConstruction

# Shrink factors of the relaxation (paper §4.5): rest lengths are shortened so that the yarns pull
# into contact while the repeat keeps its size.
SHRINK = {"knit": 0.8, "woven": 0.9, "other": 0.9}

# Typical counts per cm of each named structure (used when none are given): (ends, picks) for
# wovens, (courses, wales) for knits. Values of common apparel constructions: single jersey of
# 24–28 gauge (13 wales/cm, ~18 courses/cm), rib/garter/seed on coarser gauges, shirting to
# bottom-weight wovens (plain 30×25, drill-type twills ~42×22, satins with dense warp).
DEFAULT_COUNTS_PER_CM: dict[str, tuple[float, float]] = {
    "plain": (30.0, 25.0),
    "twill-2/1": (42.0, 22.0),
    "twill-2/2": (36.0, 20.0),
    "twill-3/1": (44.0, 22.0),
    "satin-4": (50.0, 30.0),
    "satin-5": (60.0, 35.0),
    "satin-8": (70.0, 35.0),
    "basket-2x2": (24.0, 24.0),
    "jersey": (18.0, 13.0),
    "rib-1x1": (15.0, 12.0),
    "garter": (14.0, 10.0),
    "seed": (14.0, 10.0),
}

def counts_from_label(text: str) -> tuple[float, float]:
    """Counts as a label gives them, ``"AxB"`` per cm (``x`` or ``×``), as ``(A, B)`` per metre.

    Raises:
        ValueError: not two positive numbers separated by ``x``.
    """
    parts = text.strip().lower().replace("×", "x").split("x")
    try:
        a, b = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"counts must look like 30x25 (per cm), got {text!r}") from None
    if not (math.isfinite(a) and math.isfinite(b) and a > 0 and b > 0):
        raise ValueError(f"counts must be two positive numbers per cm, got {text!r}")
    return a * 100.0, b * 100.0


# Fixed-point iterations and tolerance for the radius (the geometry's length changes by well under
# 1 % per iteration; three or four reach 1e-6).
RADIUS_ITERATIONS = 20
RADIUS_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Preset:
    """A built-in fabric: fibre, structure, areal density (g/m²), counts per cm and where the
    numbers come from."""

    fiber: str
    pattern: str
    gsm: float
    counts_per_cm: tuple[float, float]
    note: str


# The paper's five fabrics (§5). Their labels are not in the paper; the numbers are those of
# common commercial fabrics of each kind, chosen before any comparison with measurements.
PRESETS: dict[str, Preset] = {
    "cotton-jersey": Preset("cotton", "jersey", 150.0, (18.0, 13.0),
                            "T-shirt single jersey: 140–180 g/m², 28 gauge (13 wales/cm), ~18 courses/cm"),
    "wool-jersey": Preset("wool", "jersey", 190.0, (15.0, 11.0),
                          "merino single jersey: 150–250 g/m², 22–24 gauge (11 wales/cm)"),
    "polyester-jersey": Preset("polyester", "jersey", 140.0, (22.0, 16.0),
                               "sportswear single jersey: 120–160 g/m², 32 gauge (16 wales/cm)"),
    "polyester-satin": Preset("polyester", "satin-5", 100.0, (60.0, 35.0),
                              "75-denier polyester satin (charmeuse): 90–120 g/m², warp-faced 5-harness"),
    "cotton-twill": Preset("cotton", "twill-2/1", 240.0, (42.0, 22.0),
                           "cotton drill / chino: 2/1 twill, 220–280 g/m²"),
}


def named_patterns() -> dict[str, str]:
    """Every named structure and its family (``woven`` or ``knit``)."""
    return {**{name: "woven" for name in DRAFTS}, **{name: "knit" for name in STITCHES}}


@dataclass(frozen=True)
class Fabric:
    """A fabric as its label describes it (SI units).

    Attributes:
        name: label (used for recordings and material files).
        fiber: the fibre.
        structure: a named weave or knit (see :func:`named_patterns`), or ``None`` with
            ``pattern_file``.
        areal_density: kg/m²; ``None`` keeps the radius written in a ``.pyp`` file.
        counts: per metre, ``(ends, picks)`` or ``(courses, wales)``; ``None`` for the structure's
            typical counts (or, for a ``.pyp`` file, its own repeat size).
        pattern_file: a ``.pyp`` file instead of a named structure.
        yarn: how the yarn is made and which yarn model to use (default: the fibre-assembly
            model with the fibre's usual spinning system).
    """

    name: str
    fiber: Fiber
    structure: str | None = None
    areal_density: float | None = None
    counts: tuple[float, float] | None = None
    pattern_file: str | None = None
    yarn: YarnConstruction = YarnConstruction()

    def __post_init__(self) -> None:
        if not isinstance(self.yarn, YarnConstruction):
            raise ValueError(f"yarn must be a YarnConstruction, got {type(self.yarn).__name__}")
        # Before any relaxation starts: a fibre without the data its yarn model needs is bad input.
        self.yarn.check_fiber(self.fiber)
        if (self.structure is None) == (self.pattern_file is None):
            raise ValueError("give either a named pattern or a pattern file, not both or neither")
        if self.structure is not None and self.structure not in named_patterns():
            raise ValueError(
                f"unknown pattern {self.structure!r}; known patterns: {', '.join(sorted(named_patterns()))}"
            )
        if self.areal_density is not None and not (math.isfinite(self.areal_density) and self.areal_density > 0):
            raise ValueError(f"areal density must be positive, got {self.areal_density * 1e3!r} g/m²")
        if self.structure is not None and self.areal_density is None:
            raise ValueError(f"pattern {self.structure!r} needs an areal density (g/m²) to size its yarns")
        if self.counts is not None:
            if len(self.counts) != 2 or not all(math.isfinite(c) and c > 0 for c in self.counts):
                raise ValueError(f"counts must be two positive numbers, got {self.counts!r}")

    @classmethod
    def preset(cls, name: str, yarn: YarnConstruction | None = None) -> "Fabric":
        """One of :data:`PRESETS`, its yarn made as ``yarn`` (default: the fibre's usual yarn)."""
        key = name.strip().lower()
        if key not in PRESETS:
            raise ValueError(f"unknown preset {name!r}; presets: {', '.join(PRESETS)}")
        p = PRESETS[key]
        return cls(name=key, fiber=get_fiber(p.fiber), structure=p.pattern, areal_density=p.gsm * 1e-3,
                   counts=(p.counts_per_cm[0] * 100.0, p.counts_per_cm[1] * 100.0),
                   yarn=yarn or YarnConstruction())

    @property
    def yarn_density(self) -> float:
        """Mass per yarn volume (kg/m³), ``φ ρ_fibre``: sizes the yarn radius."""
        return self.yarn.yarn_density(self.fiber)

    @cached_property
    def file_pattern(self) -> YarnPattern | None:
        """The pattern read from ``pattern_file`` (``None`` for a named structure)."""
        return None if self.pattern_file is None else read_pyp(self.pattern_file)

    @property
    def family(self) -> str:
        if self.structure is not None:
            return named_patterns()[self.structure]
        return self.file_pattern.family

    @property
    def uses_file_as_is(self) -> bool:
        """A ``.pyp`` pattern without g/m² or counts: its geometry, radius and rest lengths are
        used as written."""
        return self.structure is None and self.areal_density is None and self.counts is None

    @property
    def shrink(self) -> float:
        """Rest-length factor of the relaxation: 0.8 for knits, 0.9 for wovens (paper §4.5), applied
        to a new geometry's edge lengths. A ``.pyp`` file used as is keeps its own rest lengths
        (``*RL``; HYLC's files are relaxed repeats, within 0.5 % of rest): shrinking a relaxed
        repeat again would pull its loops a fifth tighter than the structure it describes."""
        return 1.0 if self.uses_file_as_is else SHRINK[self.family]

    def pattern(self, length_override: float | None = None) -> YarnPattern:
        """The periodic repeat with the radius of the areal-density formula.

        ``length_override`` (m) replaces the geometry's yarn length L0 in the formula (the
        relaxation passes the relaxed length). Raises ``ValueError`` when the counts would make
        parallel yarns overlap.
        """
        if self.uses_file_as_is:
            return self.file_pattern
        radius = self._initial_radius()
        for _ in range(RADIUS_ITERATIONS):
            pattern = self._build(radius)
            if self.areal_density is None:
                break
            length = length_override if length_override is not None else pattern.yarn_length()
            new = radius_from_areal_density(self.areal_density, self.yarn_density, pattern.repeat_size, length)
            if abs(new / radius - 1.0) < RADIUS_TOLERANCE:
                radius = new
                pattern = self._build(radius)
                break
            radius = new
        check_packing(pattern, self.areal_density, self.yarn_density, self.counts_per_m(pattern))
        return pattern

    # -- internals ----------------------------------------------------------------------------

    def counts_per_m(self, pattern: YarnPattern | None = None) -> tuple[float, float]:
        """Counts (1/m): as given, the structure's typical ones, or those of ``pattern`` (a file's)."""
        if self.counts is not None:
            return self.counts
        if self.structure is not None:
            c = DEFAULT_COUNTS_PER_CM[self.structure]
            return c[0] * 100.0, c[1] * 100.0
        n0, n1 = pyp_thread_numbers(pattern)
        if pattern.family == "woven":
            return n0 / pattern.repeat_size[0], n1 / pattern.repeat_size[1]
        return n0 / pattern.repeat_size[1], n1 / pattern.repeat_size[0]

    def _initial_radius(self) -> float:
        if self.structure is None:
            return self.file_pattern.radius
        # A start for the fixed point: a tenth of the finer spacing.
        return 0.1 / max(self.counts_per_m())

    def _build(self, radius: float) -> YarnPattern:
        a, b = self.counts_per_m()
        if self.structure in DRAFTS:
            return weave(DRAFTS[self.structure], a, b, radius, name=self.name)
        if self.structure in STITCHES:
            return knit(STITCHES[self.structure], a, b, radius, name=self.name)
        base = self.file_pattern
        if self.counts is None:
            return base.scaled(tuple(base.repeat_size), radius)
        n0, n1 = pyp_thread_numbers(base)
        if base.family == "woven":
            size = (n0 / a, n1 / b)  # ends across x, picks along y
        else:
            size = (n1 / b, n0 / a)  # wales across x, courses along y
        return base.scaled(size, radius)


def radius_from_areal_density(areal_density: float, yarn_density: float, repeat_size, yarn_length: float) -> float:
    """``r = sqrt(ρ_fabric p_x p_y / (ρ_yarn L0 π))`` (m), paper §4.1, ``ρ_yarn`` the yarn's
    density (kg/m³: φ ρ_fibre)."""
    return math.sqrt(areal_density * repeat_size[0] * repeat_size[1] / (yarn_density * yarn_length * math.pi))


def pyp_thread_numbers(pattern: YarnPattern) -> tuple[int, int]:
    """Threads in a repeat: ``(ends, picks)`` of a woven (yarns running along y, along x) or
    ``(courses, wales)`` of a knit (its yarns, and loop heads per yarn — local maxima of y along
    each course, which must agree between courses)."""
    yarns = pattern.yarns()
    if pattern.family == "woven":
        ends = sum(1 for y in yarns if y.net_offset[1] != 0)
        return ends, len(yarns) - ends
    heads = set()
    for yarn in yarns:
        y = pattern.node_position[yarn.nodes, 1] + np.cumsum(np.vstack([[0, 0], yarn.tiles[:-1]]), axis=0)[:, 1] * pattern.repeat_size[1]
        rises = np.sign(np.diff(np.append(y, y[0] + yarn.net_offset[1] * pattern.repeat_size[1])))
        heads.add(int(np.count_nonzero((rises > 0) & (np.roll(rises, -1) < 0))))
    if len(heads) != 1:
        raise PatternError(f"pattern {pattern.name!r}: cannot tell its wales (courses have {sorted(heads)} loop heads)")
    return len(yarns), heads.pop()


def check_packing(pattern: YarnPattern, areal_density: float | None, yarn_density: float,
                  counts: tuple[float, float]) -> None:
    """Reject counts that pack more yarn than fits: a ``ValueError`` naming the numbers.

    Two touching layers of parallel cylinders hold at most ``π r`` of yarn volume per area (a
    jammed plain weave); and in a woven, neighbouring parallel yarns are 1/count apart, which must
    leave room for a diameter. ``yarn_density`` is the yarn's (φ ρ_fibre), so ``r`` is the yarn's
    own radius; real yarns also flatten where they are pressed, which round yarns cannot.
    """
    r = pattern.radius
    if areal_density is not None:
        volume = areal_density / yarn_density
        if volume > math.pi * r:
            raise ValueError(
                f"{areal_density * 1e3:.4g} g/m² of yarns of radius {r * 1e3:.3g} mm cannot fit at these counts: "
                f"their volume per area, {volume * 1e6:.3g} µm, exceeds the {math.pi * r * 1e6:.3g} µm of two jammed layers"
            )
    if pattern.family == "woven":
        for count, what in zip(counts, ("ends", "picks")):
            if 2.0 * r * count > 1.0:
                raise ValueError(
                    f"{count / 100:.4g} {what}/cm leaves {1e3 / count:.3g} mm between neighbouring yarns, less than "
                    f"their diameter {2e3 * r:.3g} mm: yarns would overlap"
                )
    elif pattern.family == "knit":
        courses, wales = counts
        # A wale holds the two legs of a loop side by side; a course at least one yarn diameter.
        if 4.0 * r * wales > 1.0 or 2.0 * r * courses > 1.0:
            raise ValueError(
                f"{courses / 100:.4g} courses/cm × {wales / 100:.4g} wales/cm leave less room than yarns of diameter "
                f"{2e3 * r:.3g} mm need (two legs per wale, one yarn per course): yarns would overlap"
            )

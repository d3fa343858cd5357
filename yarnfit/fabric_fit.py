"""A fabric's shell material end to end: relax the repeat, homogenize the samples, fit the shell,
and write the material file.

``fit_fabric(fabric)`` runs the three stages (:mod:`yarnfit.relax`, :mod:`yarnfit.homogenize`,
:mod:`yarnfit.fit`) and returns a :class:`FabricFit`; ``FabricFit.write(path)`` writes the material
file (its format: :mod:`yarnfit.material_file`).

The shell thickness is the relaxed repeat's: the span of the yarn centrelines across the fabric
plus one diameter. It only scales S and B; the engineering constants do not depend on it.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .fabric import Fabric
from .fit import COUPLING_LIMIT, ShellFit, fit_shell
from .homogenize import default_ranges, sample_groups, solve_group, solve_samples
from .material_file import MaterialFile
from .relax import RelaxedRepeat, relax
from .samples import SampleRanges, SampleResult, SampleSpec, design_size, levels_for, sample_design
from .shell import ShellMaterial
from .tasks import Backend

# Four magnitudes per family and sign, from 0.1 % (1 /m) to the range (the stretches pressed too,
# to 10 % at most), free-width pulls along weft, warp and the bias at nine strains from 0.1 to 10 %
# (samples.uniaxial_strains), and the undeformed sample (93 in all; a woven, pulled along both
# biases, 102): each stretch and shear curve from four points a side and each free-width pull from
# nine, at about a second per small-strain sample.
DEFAULT_LEVELS = 4
DEFAULT_SAMPLES = design_size(DEFAULT_LEVELS)

# The structure families whose membrane samples are loaded with the fibre's friction unless the
# caller says otherwise (docs/design.md §3, "Knits are fitted to their loading response").
# A knit's loops slide through one another at their crossings, and friction there is what a
# tensile test and a cut strip of it pull against: its loading response is 1.3–1.9 times the
# paper's frictionless minimisers, and fitted to it the shell meets the largest yarn-level knit
# strips within 20 % at 19 of 26 points where the frictionless fit meets 5 (session 45), for
# about 3 times the samples' time (the jerseys' fits 12.5–15.7 s on two cores, session 46). A
# woven's crossings barely slide below its jams: the cotton twill's two fits meet its strips alike (4 and 3 of 7),
# while the loading paths of a polyester woven (range 40 %, 80 load steps) cost minutes
# (the satin: 505 s against 34 s).
FRICTION_LOADED_FAMILIES = frozenset({"knit"})


# The structure families whose shell is fitted even in the shear (fit.fit_shell(even_shear=True)).
# A knit's loops are mirror-symmetric and lean one way or the other (its skew) only as a broken
# symmetry its relaxation picks (docs/design.md §5), set in a real jersey by its yarns' twist, which
# the yarn model does not carry: fitted to one side's lean its shell pulled 3-9 times harder along
# −45° than along +45° (session 46). A woven's twill or satin line sets the side it shears stiffer
# on, which its samples measure (the cotton twill's pure shear 9 times stiffer at −10 % than +10 %).
EVEN_SHEAR_FAMILIES = frozenset({"knit"})


def shears_evenly(fabric: Fabric) -> bool:
    """Whether ``fabric``'s shell is fitted even in the shear: knits (:data:`EVEN_SHEAR_FAMILIES`)."""
    return fabric.family in EVEN_SHEAR_FAMILIES


def samples_both_biases(fabric: Fabric) -> bool:
    """Whether ``fabric``'s design pulls it along both biases (+45° and −45°,
    :func:`yarnfit.samples.sample_design` with ``both_biases``): where its shell keeps the shear's
    two signs apart (not :func:`shears_evenly`). Pulled along +45° alone, such a shell met the other
    bias with its pure shear's stiffness, which a bias pull relaxes: the cotton twill's shell pulled
    53 N/m at 2 % along −45° where its yarns pull 3.7 (and 0.36 / 0.34 along +45°; session 47). A
    knit's shell is even in the shear and its jersey repeat pulls alike along both biases without
    friction (cotton jersey's pulls equal to four digits at 0.1–10 %): the other bias's samples
    would only repeat the first's. (With friction, on the loading paths a knit's samples follow,
    the wool and polyester jerseys' two biases part at 5–10 % as their skew slides: wool 9.39 /
    24.3 N/m along −45° against 8.31 / 16.4 along +45°, polyester 4.06 / 7.96 against 4.47 / 12.3,
    cotton alike; the even shell follows the +45° side, along which the strips are cut.)"""
    return not shears_evenly(fabric)


def loads_with_friction(fabric: Fabric) -> bool:
    """Whether ``fabric``'s membrane samples are loaded with friction when nobody says: knits
    (:data:`FRICTION_LOADED_FAMILIES`). Reads a ``.pyp`` file to learn its family."""
    return fabric.family in FRICTION_LOADED_FAMILIES


class UnusableRelaxation(ValueError):
    """The repeat's relaxation did not converge or leaves yarns overlapping: nothing to fit."""


def shell_thickness(relaxed: RelaxedRepeat) -> float:
    """Thickness ``h`` (m) of the relaxed repeat: span of the centrelines normal to the fabric
    plus one yarn diameter."""
    z = relaxed.state.node_position[:, 2]
    return float(z.max() - z.min() + 2.0 * relaxed.radius)


@dataclass(frozen=True, eq=False)
class FabricFit:
    """A fabric fitted end to end.

    Attributes:
        fabric: the input.
        relaxed: the relaxed repeat.
        ranges: the largest sampled stretch and curvature.
        samples: every solved sample, in design order.
        fit: the shell fit (its material has thickness :func:`shell_thickness`).
        seconds: wall time per stage, ``{"relax", "homogenize", "fit"}``.
        sample_friction: the friction coefficient μ the membrane samples were loaded with (0: the
            paper's frictionless minimisers; > 0: loading paths with the fibre's friction,
            :mod:`yarnfit.homogenize.loading`).
    """

    fabric: Fabric
    relaxed: RelaxedRepeat
    ranges: SampleRanges
    samples: list[SampleResult]
    fit: ShellFit
    seconds: dict
    sample_friction: float = 0.0

    @property
    def material(self) -> ShellMaterial:
        return self.fit.material

    def to_dict(self) -> dict:
        """The material file's contents (see :mod:`yarnfit.material_file`)."""
        return MaterialFile.from_fit(self).data

    def write(self, path: str | os.PathLike) -> Path:
        """Write the material file (directories created, written whole or not at all); returns
        its path."""
        return MaterialFile.from_fit(self).write(path)


def relax_for_fit(fabric: Fabric, on_relax_iteration: Callable | None = None,
                  on_relax_start: Callable | None = None) -> RelaxedRepeat:
    """The fabric's relaxed repeat (:func:`yarnfit.relax.relax`), or :class:`UnusableRelaxation`
    when it did not converge or leaves yarns overlapping."""
    return _usable(fabric, relax(fabric, on_iteration=on_relax_iteration, on_start=on_relax_start))


def _usable(fabric: Fabric, relaxed: RelaxedRepeat) -> RelaxedRepeat:
    """``relaxed``, or :class:`UnusableRelaxation` when it did not converge or leaves overlaps."""
    if not relaxed.valid:
        raise UnusableRelaxation(f"the relaxation of {fabric.name!r} is not usable: converged {relaxed.converged}, "
                                 f"worst overlap {100 * relaxed.penetration:.3g} % of the diameter ({relaxed.residual})")
    return relaxed


def design_specs(relaxed: RelaxedRepeat, samples: int = DEFAULT_SAMPLES,
                 ranges: SampleRanges | None = None, both_biases: bool = False) -> list[SampleSpec]:
    """The samples a fit of about ``samples`` solves: :func:`yarnfit.samples.sample_design` over
    ``ranges`` (default :func:`yarnfit.homogenize.default_ranges` of the relaxed repeat), with the
    other bias's pulls if ``both_biases`` (:func:`samples_both_biases`)."""
    return sample_design(ranges or default_ranges(relaxed), levels_for(samples), both_biases)


def design_groups(samples: int = DEFAULT_SAMPLES, friction: bool = False,
                  both_biases: bool = False) -> list[tuple[int, ...]]:
    """:func:`~yarnfit.homogenize.sample_groups` of the design of about ``samples`` samples, known
    before the repeat is relaxed (a catalogue's task graph): default ranges (compression sampled)
    change the design's magnitudes from one fabric to the next, never which family and sign each
    sample is, which is all the groups depend on (so any ranges give them).
    :func:`solve_design_group` checks them against the relaxed repeat's own design."""
    return sample_groups(sample_design(SampleRanges(stretch=0.1, curvature=10.0), levels_for(samples), both_biases),
                         friction)


def solve_design_group(relaxed: RelaxedRepeat, samples: int, indices: tuple[int, ...],
                       friction: bool = False, both_biases: bool = False) -> list[SampleResult]:
    """The samples ``indices`` of :func:`design_specs` (default ranges, ``both_biases``), one group
    of :func:`design_groups` (with ``friction``: the membrane samples on load paths with the fibre's
    friction), solved by :func:`~yarnfit.homogenize.solve_group`: one task of a fit whose design is
    only known once the repeat is relaxed (a catalogue's).

    Raises:
        ValueError: ``indices`` are not one group of the relaxed repeat's design.
    """
    specs = design_specs(relaxed, samples, both_biases=both_biases)
    if tuple(indices) not in sample_groups(specs, friction):
        raise ValueError(f"samples {list(indices)} are not one group of the {len(specs)}-sample design")
    return solve_group(relaxed, [specs[i] for i in indices], relaxed.fiber.friction if friction else None)


def fit_solved(fabric: Fabric, relaxed: RelaxedRepeat, results: list[SampleResult], model: str = "full",
               coupling_limit: float | None = COUPLING_LIMIT, ranges: SampleRanges | None = None,
               seconds: dict | None = None, sample_friction: float = 0.0) -> FabricFit:
    """The shell fitted to the solved samples ``results`` (see :func:`fit_fabric`; their membrane
    samples loaded with friction ``sample_friction``)."""
    seconds = dict(seconds or {})
    start = time.perf_counter()
    shell = fit_shell(results, shell_thickness(relaxed), model=model, coupling_limit=coupling_limit,
                      even_shear=shears_evenly(fabric))
    seconds["fit"] = time.perf_counter() - start
    return FabricFit(fabric, relaxed, ranges or default_ranges(relaxed), results, shell, seconds, sample_friction)


def fit_fabric(
    fabric: Fabric,
    samples: int = DEFAULT_SAMPLES,
    model: str = "full",
    ranges: SampleRanges | None = None,
    workers: int | None = None,
    relaxed: RelaxedRepeat | None = None,
    on_relaxed: Callable[[RelaxedRepeat], None] | None = None,
    on_sample: Callable[[int, int, SampleResult], None] | None = None,
    on_relax_iteration: Callable | None = None,
    on_relax_start: Callable | None = None,
    coupling_limit: float | None = COUPLING_LIMIT,
    backend: Backend | None = None,
    friction: bool | None = None,
) -> FabricFit:
    """Relax ``fabric`` (unless ``relaxed`` is given), solve about ``samples`` samples over
    ``ranges`` (default :func:`yarnfit.homogenize.default_ranges`) on ``workers`` processes, and fit
    the shell (``model`` "full" or "paper"). ``on_relax_iteration`` and ``on_relax_start`` go to
    :func:`yarnfit.relax.relax`; ``on_relaxed(relaxed)`` is called once the repeat is relaxed,
    ``on_sample(done, total, result)`` after each sample. ``backend`` runs the samples instead of
    a pool of ``workers`` (:mod:`yarnfit.tasks`: a Dask cluster). ``coupling_limit`` bounds the couplings
    (see :func:`yarnfit.fit.fit_shell`; ``None``: unbounded, an indefinite fit raises).
    ``friction``: load the membrane samples from rest with the fibre's friction
    (:func:`yarnfit.homogenize.solve_loading_samples`: the fabric's loading response, what a
    tensile test and a cut strip measure) instead of the paper's frictionless minimisers; bends
    stay frictionless. ``None`` (the default): with friction for knits, without for the rest
    (:func:`loads_with_friction`).

    Raises ``ValueError`` for bad options, :class:`UnusableRelaxation` for a relaxation that did
    not converge or leaves overlaps, :class:`yarnfit.fit.IndefiniteFitError` (only with
    ``coupling_limit=None``) for a fit that is not positive definite, naming the sample family at
    fault.
    """
    levels_for(samples)  # validates the count before the relaxation's minutes
    if model not in ("full", "paper"):
        raise ValueError(f"model must be 'full' or 'paper', got {model!r}")
    if friction is None:
        friction = loads_with_friction(fabric)
    seconds = {}
    start = time.perf_counter()
    relaxed = relax_for_fit(fabric, on_relax_iteration, on_relax_start) if relaxed is None else _usable(fabric, relaxed)
    seconds["relax"] = time.perf_counter() - start
    if on_relaxed is not None:
        on_relaxed(relaxed)
    ranges = ranges or default_ranges(relaxed)
    specs = design_specs(relaxed, samples, ranges, samples_both_biases(fabric))
    start = time.perf_counter()
    coefficient = relaxed.fiber.friction if friction else 0.0
    results = solve_samples(relaxed, specs, workers=workers, on_sample=on_sample, backend=backend,
                            coefficient=coefficient if friction else None)
    seconds["homogenize"] = time.perf_counter() - start
    return fit_solved(fabric, relaxed, results, model, coupling_limit, ranges, seconds, coefficient)

"""The strain-stiffening membrane's fit: a :class:`~yarnfit.shell.RidgeMembrane` from the same
membrane samples as the linear fit (:func:`yarnfit.fit.fit_shell` calls it; ``docs/design.md`` §3).

The membrane (``fit_shell(membrane="nonlinear")``, the default) is a
:class:`~yarnfit.shell.RidgeMembrane`: a sum of one-sided quadratic ridges along candidate strain
directions (:func:`ridge_candidates`), whose energy is linear in each ray's tangent
stiffness between consecutive knots. Those tangents, each ``>= 0`` (convex by construction), are
fitted to the *relative* energy error of every membrane sample (weight ``1/Ū²``, so a sample at
0.1 % strain counts as much as one at the range), to each uniaxial sample's transverse stress
(zero at a free width; the sample's ``across_slope`` where known) and to its stress along the
pull (its ``pull_slope``, where known), by
non-negative least squares, with weak rows that choose among equal fits the one with
the fewest kinks (:data:`RIDGE_SMOOTHING`). The material's ``S`` stays the linear fit; the
bending group is the linear fit's in both models. What the membrane cannot represent is said where
it is defined (:class:`~yarnfit.shell.RidgeMembrane`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import nnls

from .samples import SampleResult
from .shell import RidgeMembrane, ShellMaterial, bending_strain, membrane_strain

__all__ = ["fit_ridge_membrane", "ridge_candidates"]

# Samples a direction's own pure family (weft or warp stretch, shear) needs away from zero before
# the strain-stiffening fit measures that direction's residual stress: with fewer, the linear term
# takes up whatever the ridges miss (−2.8 kN/m from one level).
MIN_RESIDUAL_SAMPLES = 3
# A uniaxial sample whose Ū is below this fraction of the energy a quadratic law through the
# group's largest sample gives at its strain is slack (zero to its solve's accuracy; straight yarns
# on the bias: ~1e-10 of it) and gets no stress rows. The presets' bias pulls: the knits' ~5e-4 of
# it, the twill's 1e-5 … 2e-4, the satin's 4e-7 … 5e-6 (its shear is 1e-5 of its weft stiffness:
# near a mechanism, and below 0.1 % treated as one).
SLACK_ENERGY_REL = 1.0e-6
# Relative weighting of the strain-stiffening fit: a sample's energy error is divided by its energy
# Ū, but not by less than this fraction of that quadratic law. A slack sample (Ū ≈ 0: a knit's
# wales under compression) would otherwise get an unbounded weight. The same fraction as
# SLACK_ENERGY_REL: every sample that is not slack is judged by its relative error. At 1e-3 (until
# session 37) the wovens' bias pulls, 1e-5 … 2e-4 of the law, were judged by absolute errors at a
# thousandth of it, and their shells came out 4-6 times too stiff on the bias (satin +397 / −48 /
# +565 %, twill +342 / +40 / −32 % against their periodic pulls at 2 / 5 / 10 %).
RELATIVE_WEIGHT_FLOOR = SLACK_ENERGY_REL
# The strain-stiffening membrane's candidate ridges (ridge_candidates). A fan of directions in the
# normal-strain plane every 15°: with 7.5° the five presets' periodic free-width pulls at 2/5/10 %
# were met no better (24 of 30 within 20 % against 27; session 35's trials on the same samples), and
# the unknowns double. Around each principal direction of the linear fit's S, offsets of 0, ±1 and
# ±3°: a knit's S is near rank one (coupling 0.99+), its stiff combination (the yarn length)
# between fan directions; without them cotton jersey's pure stretches came out 60 % off.
RIDGE_FAN_STEP_DEG = 15.0
RIDGE_PRINCIPAL_OFFSETS_DEG = (-3.0, -1.0, 0.0, 1.0, 3.0)
# Mixed rays: every direction of that fan (over 360°) raised out of the normal-strain plane by these
# elevations towards either sign of the shear; for a knit (even_shear) each tied to its mirror in
# the shear, as its shear axis is (one tangent per pair: the membrane even in the shear,
# orthotropic; _shear_ties), for a woven each with its own. A fabric pulled on the bias shears
# its yarn frame and relaxes into small normal strains of its yarns (the twill at 4 %: E00, E11 ≈
# −0.002, −0.005 under 2 E01 = 0.088) that cost less together than the shear alone; a sum of separate
# normal and shear rays can only add their energies, and left the wovens' bias pulls 20-30 % too
# soft once their samples were weighted (session 37, the presets' samples refitted against their
# periodic pulls at 2 / 5 / 10 %: without mixed rays 29 of 30 weft and warp pulls and 9 of 15 bias
# ones within 20 %; at 45°, 29 and 15; at 30° and 60°, 29 and 14, the satin's bias at 2 % +95 %;
# untied, a jersey's mixed rays took sides in the shear and its weft pull sheared: −51 % at 10 %).
# A woven's are untied since its design pulls it along both biases (session 47,
# fabric_fit.samples_both_biases): tied, the pairs cannot be both the cotton twill's +45° pull
# and its ten-times-stiffer −45° one, and the fit gave up its weft pull at 1 % for them (−55 %);
# untied, its pulls along weft, warp and both biases met its periodic ones within 20 % at 18 of 20
# points (0.1, 1, 2, 5, 10 %; the satin 16), the axis pulls shearing a little (2 E01 ≤ 0.04 at
# 10 %), which the axis samples, their shear held at 0, do not measure.
# Tried at 10° as well (session 46, not kept): a pure shear (normal strains held at 0) is several
# times stiffer than the shear a bias pull reaches with the small normal strains of its mechanism,
# and a ridge that charges the one and not the other lies close to the normal-strain plane. With 10°
# and 45° the fits met their own shear and bias samples (relative RMS, twill 0.10 and 0.84 → 0.00
# and 0.00; wool jersey's loading samples 0.50 and 0.23 → 0.19 and 0.00) and the strips as well
# as before (24 of 34 cells), but the ridges' tangent anywhere within ±10 % strain, which the
# MuJoCo split's implicit part must cover (mujoco.split.membrane_to_cover), grew 1.8 times for the
# twill (built-in E 312 → 548 MPa) and its weft strips no longer came to rest at 0.2 % within the
# stretch scene's hold (docs/design.md §3, session 46).
RIDGE_MIXED_ELEVATIONS_DEG = (45.0,)
# Knots per ray besides 0: log-spaced from RIDGE_LEAST_KNOT (0.2 %, twice the smallest sampled
# strain, so the 0.1 % samples see the tangent at zero alone) to the farthest sample along the ray.
# Six resolve a knit's jam (its free-width warp energy grows sevenfold from 5 to 7.5 %); ten
# followed the samples no better (the same trials). Twelve since the uniaxial pulls are sampled
# within their two largest intervals too (session 52, samples.uniaxial_strains: 2.2, 3.2, 4.6,
# 6.8, 10 %), a ratio of 1.47 between samples where six knots along a ray reaching 10.5 % (a 10 %
# pull's Green strain) are 1.9 apart (the last at 1.4, 2.8, 5.4 %, then one straight stress segment
# to 10.5 %, across the 6.8 % sample where the twill's bias locks) and twelve 1.4 (the last at 2.8,
# 3.9, 5.4, 7.5 %). The five presets refitted from their own samples and pulled between them
# (validation/periodic_pulls.py at 0.1, 1, 2, 3, 4.6, 5.5, 6, 6.66, 7.5, 8.5, 10 % along weft, warp
# and both biases; 220 points),
# points beyond 20 % of the periodic pulls, with 6 / 8 / 10 / 12 / 14 / 16 knots: 28 / 27 / 24 /
# 19 / 18 / 16 (42 before the new samples, six knots); the twill 8 / 6 / 3 / 3 / 0 / 1, but the
# satin's bias at 2 %, whose force is 1e-4 of its weft's, −8 / … / +39 / +51 / +75 / +82 %: the
# more knots, the freer a ray's tangent where the energies are too small to pin it. Of the misses
# with twelve, 10 are the knits' −45° pulls, which their designs do not sample.
RIDGE_LEAST_KNOT = 2.0e-3
RIDGE_KNOTS = 12
# Weight of the rows that ask a ray's tangent not to jump between segments, nor to differ from the
# opposite ray's at zero (fit_ridge_membrane), squared, against the samples' relative energy
# errors, with the jump measured in units of the linear fit's stiffest tangent: a jump of that size
# costs what a 1e-3 relative error of one sample does, so the data decide wherever they can and the
# rows only choose among equal fits.
RIDGE_SMOOTHING = 1e-6
# Iteration limit of the non-negative least squares (an active-set method over a few hundred
# unknowns: each iteration frees or binds one, so a few times their number; scipy's default is 3x).
RIDGE_SOLVE_ITERATIONS = 10000
# Fitted tangents within this fraction of the stiffest one of 0 or of their neighbour on the ray are
# snapped to it (_ridge_membrane): the active-set solve leaves exact zeros and values at the data's
# scale; 1e-9 only removes round-off.
NEGLIGIBLE_RIDGE_REL = 1e-9




def fit_ridge_membrane(
    pairs: list[tuple[SampleResult, float]], h: float, linear: ShellMaterial,
    residual_names: tuple[str, str, str] | None = None, even_shear: bool = True,
) -> tuple[RidgeMembrane | None, list[str], dict[str, list[float]], dict[str, float]]:
    """The strain-stiffening membrane (:class:`~yarnfit.shell.RidgeMembrane`) fitted to the
    membrane samples (module docstring).

    ``pairs``: each membrane sample with its energy relative to the undeformed one (J/m²);
    ``h``: the shell's thickness (m); ``linear``: the linear fit, whose principal strain directions
    join the ridges' fan. Returns ``(the membrane or None, notes, Voigt strain range per direction,
    residual stress (N/m) by name)``; ``residual_names`` (the weft, warp and shear terms' names,
    :data:`yarnfit.fit.RESIDUAL_STRESS_NAMES`) fits the residual-stress terms linear in the strain
    along; ``even_shear`` ties each ray with a shear part to its mirror (:func:`_shear_ties`).

    The candidate ridges (:func:`ridge_candidates`) make ψ linear in the tangent stiffness of each
    ray's segments between knots (:func:`_ridge_columns`), so the fit is a non-negative linear
    least-squares problem (every segment's tangent ``>= 0``: each ray's ψ convex, so their sum is)
    solved exactly by the Lawson–Hanson active-set method. A tangent may fall from one segment
    to the next: a yarn's energy in the Green strain softens (a straight linear yarn's
    ``½ k (√(1 + 2E) − 1)²``), which stiffening-only ridges cannot follow (they put a straight
    yarn's small-strain stretch 4 % low at a 10 % range, 98 % at 40 %). The base stays 0.
    """
    samples = [s for s, _ in pairs]
    eps = np.stack([membrane_strain(s.I) for s in samples])
    target = np.array([e for _, e in pairs])
    strain_range = {d: [float(eps[:, k].min()), float(eps[:, k].max())] for k, d in enumerate(("s00", "s11", "s22"))}
    directions, knots = ridge_candidates(eps, linear, even_shear)
    columns = _ridge_columns(eps, directions, knots, h)
    stress_names, stress_voigt = [], []
    if residual_names is not None:
        # A direction's residual stress needs its own family's samples: with fewer, the linear term
        # takes up whatever the ridges miss.
        for k, family in enumerate(("weft_stretch", "warp_stretch", "shear")):
            if sum(s.family == family and s.parameter != 0.0 for s in samples) >= MIN_RESIDUAL_SAMPLES:
                stress_names.append(residual_names[k])
                stress_voigt.append(k)
    residual_columns = eps[:, stress_voigt]
    A = np.hstack([columns, residual_columns])

    # Relative weights: the residual is divided by Ū, floored at RELATIVE_WEIGHT_FLOOR of the
    # quadratic law through the sample of largest Ū (not of largest strain: a bias pull of straight
    # yarns strains the sheet most and stores nothing).
    magnitude = np.linalg.norm(eps, axis=1)
    largest = int(np.argmax(target))
    quadratic = max(target[largest], 0.0) * (magnitude / magnitude[largest]) ** 2
    scale = np.maximum(np.abs(target), RELATIVE_WEIGHT_FLOOR * quadratic)
    if not np.all(scale > 0.0):
        raise ValueError("the membrane samples carry no energy: they cannot determine a membrane stiffness")
    rows, b = A / scale[:, None], target / scale
    # A uniaxial sample's free strains are where the yarn-level energy is least, so the shell's
    # stress across the pull (and, on the bias, in the pull frame's shear) vanishes there too;
    # where the search stopped at an end of its interval (a knit that would widen under a
    # wale-wise pull stops at E⊥ = 0), the stress across is the sample's across_slope instead. Its
    # stress along the pull is the yarn-level one, the sample's pull_slope (dŪ/de at the free
    # strains). One row each, in energy units (the stress times the pull's own Green strain e, so a
    # stress across is judged against the pulling stress, which puts ~2 Ū in that unit) and
    # weighted as the sample's energy row. Times the transverse strain instead, a material that
    # does not contract (Poisson 0) had no say on its stress across. Energies alone fix the force
    # only on average between two samples: a knit's pull stiffening 18x from 2 to 10 % came back
    # 25-68 % off at 5 %, between the samples at 4 and 10 %, with every energy exact.
    def stress_row(i: int, change: np.ndarray) -> np.ndarray:
        """The derivative of sample ``i``'s energy along the symmetric Green strain change
        ``change`` ``(2, 2)``: the ridges' columns and the residual stresses'."""
        voigt = bending_strain(change)  # (E00, E11, 2 E01): the same map as κ's of II
        stresses = [float(voigt[k]) for k in stress_voigt]
        return np.concatenate([_ridge_columns(eps[i:i + 1], directions, knots, h, voigt)[0], stresses])

    # A slack sample (straight yarns pulled on the bias turn out of the way: Ū 1e-13 … 1e-10 J/m²)
    # carries stresses at its solve's noise, which the floor's weight would enforce (they put the
    # straight yarns' weft stretch 1.0 % low): its energy row alone says it is slack.
    taut = np.abs(target) > SLACK_ENERGY_REL * quadratic
    stresses = []
    for i, sample in enumerate(samples):
        angle = sample.family.uniaxial_angle
        if angle is None or not taut[i]:
            continue
        along, across = np.array([math.cos(angle), math.sin(angle)]), np.array([-math.sin(angle), math.cos(angle)])
        weight = abs(0.5 * ((1.0 + sample.parameter) ** 2 - 1.0)) / scale[i]  # the pull's e over the scale
        slope = sample.across_slope if math.isfinite(sample.across_slope) else 0.0
        wanted = [(np.outer(across, across), slope)]
        if sample.family.uniaxial_axis is None:  # on the bias the pull frame's shear is free too
            wanted.append((np.outer(along, across) + np.outer(across, along), 0.0))
        if math.isfinite(sample.pull_slope):
            wanted.append((np.outer(along, along), sample.pull_slope))
        stresses += [(stress_row(i, change) * weight, value * weight) for change, value in wanted]
    if stresses:
        rows = np.vstack([rows] + [row for row, _ in stresses])
        b = np.concatenate([b, [value for _, value in stresses]])
    # Many tangents fit the samples' energies equally well (a few hundred segments, tens of
    # samples), and they differ between the samples: in a pull's force, the energy's slope (a StVK
    # material's 10 % weft pull came back 1.6 % off with its energies exact). Rows that ask each
    # ray's tangent not to jump between segments, RIDGE_SMOOTHING weak, pick among them the one
    # with the fewest and smallest kinks: a quadratic where the data are one.
    # Likewise a ray's first tangent and its opposite ray's: the tangent at zero strain should not
    # depend on the strain's sign unless the samples say so (a StVK material's compression, which
    # only the uniaxial samples see, came back 50 % soft along some combinations).
    same = np.flatnonzero(_same_ray(directions))
    first = np.flatnonzero(knots == 0.0)
    opposite = [(i, j) for i in first for j in first if j > i and np.array_equal(directions[j], -directions[i])]
    pairs = [(k + 1, k) for k in same] + opposite
    jumps = np.zeros((len(pairs), A.shape[1]))
    weight = math.sqrt(RIDGE_SMOOTHING) / max(linear.s00, linear.s11, linear.s22)
    for row, (i, j) in enumerate(pairs):
        jumps[row, i], jumps[row, j] = weight, -weight
    rows, b = np.vstack([rows, jumps]), np.concatenate([b, np.zeros(len(pairs))])
    ties = _shear_ties(directions, knots, even_shear)
    rows = np.hstack([rows[:, :len(knots)] @ ties, rows[:, len(knots):]])
    norms = np.linalg.norm(rows, axis=0)
    engaged = norms > 0.0  # a residual stress no sample strains has no say: left at 0
    scaled = rows[:, engaged] / norms[engaged]
    # Non-negative least squares (Lawson–Hanson, exact, ~0.05 s here where the bounded-variable
    # method took 20 s); a residual stress, of either sign, as the difference of two.
    signed = np.concatenate([np.zeros(ties.shape[1], bool), np.ones(len(stress_names), bool)])[engaged]
    notes = []
    try:
        x, _ = nnls(np.hstack([scaled, -scaled[:, signed]]), b, maxiter=RIDGE_SOLVE_ITERATIONS)
    except RuntimeError as exc:  # the iteration limit
        notes.append(f"the strain-stiffening membrane's fit failed ({exc}): the material carries the linear membrane")
        return None, notes, strain_range, {}
    solution = x[:scaled.shape[1]].copy()
    solution[signed] -= x[scaled.shape[1]:]
    values = np.zeros(len(engaged))
    values[engaged] = solution / norms[engaged]
    tangents = ties @ values[:ties.shape[1]]
    stress = dict(zip(stress_names, values[ties.shape[1]:].tolist()))
    membrane = _ridge_membrane(directions, knots, tangents)
    notes.append(f"strain-stiffening membrane: {len(membrane.ridges)} ridges of {len(knots)} candidates")
    return membrane, notes, strain_range, stress


def ridge_candidates(eps: np.ndarray, linear: ShellMaterial, even_shear: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The candidate ridges of the strain-stiffening fit for membrane strains ``eps (n, 3)``:
    ``(directions (k, 3), knots (k,))``.

    Directions: a fan in the normal-strain plane every :data:`RIDGE_FAN_STEP_DEG`, plus the linear
    fit's principal strain directions and :data:`RIDGE_PRINCIPAL_OFFSETS_DEG` around them (a knit's
    stiff combination, the yarn length, lies between fan directions: its near-rank-one stretch
    energies need it exactly), each with both signs; and ``±`` the shear axis. Knots per ray: 0 (a
    one-sided tangent at zero) and :data:`RIDGE_KNOTS` log-spaced from :data:`RIDGE_LEAST_KNOT` to
    the largest ``n·ε`` the samples reach along it (none where they reach less than that), along it
    or its mirror in the shear for a ray tied to its mirror (:func:`_shear_ties`, ``even_shear``)."""
    principal = np.linalg.eigh(linear.S[:2, :2])[1].T
    angles = np.concatenate([np.arange(0.0, 180.0, RIDGE_FAN_STEP_DEG)]
                            + [math.degrees(math.atan2(v[1], v[0])) + np.array(RIDGE_PRINCIPAL_OFFSETS_DEG)
                               for v in principal])
    angles = np.unique(np.round(np.mod(angles, 180.0), 9))
    plane = np.stack([np.cos(np.radians(angles)), np.sin(np.radians(angles)), np.zeros(len(angles))], axis=1)
    rays = [plane, -plane, [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]]
    around = np.radians(np.arange(0.0, 360.0, RIDGE_FAN_STEP_DEG))
    for elevation in np.radians(RIDGE_MIXED_ELEVATIONS_DEG):
        c, s = math.cos(elevation), math.sin(elevation)
        for sign in (1.0, -1.0):
            rays.append(np.stack([c * np.cos(around), c * np.sin(around), np.full(len(around), sign * s)], axis=1))
    directions, knots = [], []
    for n in np.concatenate(rays):
        # A ray with a shear part and its mirror in the shear share their knots (their tangents
        # are tied).
        reach = float(max(np.max(eps @ n),
                          np.max(eps @ (n * [1.0, 1.0, -1.0])) if _tied_in_shear(n, even_shear) else -np.inf))
        ray_knots = [0.0]
        if reach > RIDGE_LEAST_KNOT:
            ray_knots += np.geomspace(RIDGE_LEAST_KNOT, reach, RIDGE_KNOTS, endpoint=False).tolist()
        directions += [n] * len(ray_knots)
        knots += ray_knots
    return np.array(directions), np.array(knots)


def _tied_in_shear(direction: np.ndarray, even_shear: bool) -> bool:
    """A ray whose tangents are its mirror's in the shear: with ``even_shear``, every ray with a
    shear part (the shear axis and the mixed rays)."""
    return bool(even_shear and direction[2] != 0.0)


def _shear_ties(directions: np.ndarray, knots: np.ndarray, even_shear: bool = True) -> np.ndarray:
    """``(k, m)``: the candidates' tangents from ``m`` unknowns; with ``even_shear`` a ray with a
    shear part (a mixed ray, the shear axis) and its mirror in the shear (``n2 → −n2``, the same
    knots) from one, so the membrane is even in the shear: an orthotropic fabric's energy does not
    change when its shear changes sign. Every other candidate has its own unknown. Untied, a
    jersey's mixed rays took sides in the shear and its weft pull sheared (session 37).

    The shear axis's two signs were left untied until session 46, and the jerseys' shells followed
    their repeats' skew: pulled along −45° they pulled 3-9 times harder than along +45°, where the
    bias samples are (polyester jersey's loading shell 15.0 against 1.71 N/m at 2 %). Which way a
    jersey's loops lean is a broken symmetry its relaxation picks (docs/design.md §5, "The
    jerseys' relaxations land on their mirror images"), set in a real jersey by its yarns' twist,
    which the yarn model does not carry; so the shell follows the skew on average over the two
    signs, as :class:`~yarnfit.shell.RidgeMembrane` says. A woven's twill or satin line sets the
    side it shears stiffer on (the cotton twill's pure shear 9 times stiffer at −10 % than at
    +10 %, its −45° pull ten times its +45° one): ``even_shear=False`` keeps every ray's sides
    apart, the design pulling it along both biases (:func:`yarnfit.fabric_fit.samples_both_biases`)."""
    index = {(tuple(d), float(t)): j for j, (d, t) in enumerate(zip(directions.tolist(), knots))}
    unknown = np.empty(len(knots), dtype=np.int64)
    count = 0
    for j, (d, t) in enumerate(zip(directions.tolist(), knots)):
        mirror = index.get(((d[0], d[1], -d[2]), float(t)), j) if _tied_in_shear(directions[j], even_shear) else j
        if mirror < j:
            unknown[j] = unknown[mirror]
        else:
            unknown[j], count = count, count + 1
    ties = np.zeros((len(knots), count))
    ties[np.arange(len(knots)), unknown] = 1.0
    return ties


def _same_ray(directions: np.ndarray) -> np.ndarray:
    """``(k − 1,)`` bool: candidate ``j + 1`` lies on candidate ``j``'s ray (the next knot along it;
    :func:`ridge_candidates` keeps a ray's candidates contiguous)."""
    return np.all(directions[1:] == directions[:-1], axis=1)


def _ridge_columns(eps: np.ndarray, directions: np.ndarray, knots: np.ndarray, h: float,
                   change: np.ndarray | None = None) -> np.ndarray:
    """``(n, k)``: the energy per reference area (J/m²) of each candidate's *segment* with unit
    tangent stiffness at Voigt strains ``eps (n, 3)``; with ``change`` (Voigt ``(3,)``), its
    derivative along that strain direction.

    Along a ray ``n`` with knots ``t_0 < t_1 < …`` the membrane's tangent is ``s_k`` on ``[t_k,
    t_{k+1})``; segment k's energy is ``½ h (max(x − t_k, 0)² − max(x − t_{k+1}, 0)²)`` in ``x = n·ε``
    (the last one's ``t_{k+1}`` is infinite), so ψ along the ray is ``Σ_k s_k`` times it and its
    ridge stiffnesses are ``c_k = s_k − s_{k−1}``. Candidates of one ray are contiguous, their knots
    increasing (:func:`ridge_candidates`)."""
    following = np.full(len(knots), np.inf)
    same = _same_ray(directions)
    following[:-1][same] = knots[1:][same]
    x = eps @ directions.T
    start, end = np.maximum(x - knots, 0.0), np.maximum(x - following, 0.0)
    if change is None:
        return 0.5 * h * (start**2 - end**2)
    return h * (start - end) * (directions @ np.asarray(change, dtype=np.float64))


def _ridge_membrane(directions: np.ndarray, knots: np.ndarray, tangents: np.ndarray) -> RidgeMembrane:
    """The :class:`RidgeMembrane` of fitted segment tangents ``s (k,)`` (:func:`_ridge_columns`):
    ridge stiffnesses ``c_k = s_k − s_{k−1}`` along each ray. Round-off is snapped first, within
    :data:`NEGLIGIBLE_RIDGE_REL` of the stiffest tangent: a tangent to 0, a segment to its
    predecessor's tangent (the data left them equal). Only then are the differences taken, so each
    ray's running sum is its snapped tangent, never below 0; dropping small differences instead
    left a ray's last tangent at −(the difference dropped)."""
    threshold = NEGLIGIBLE_RIDGE_REL * max(float(np.max(tangents, initial=0.0)), 1e-300)
    same = _same_ray(directions)
    snapped = np.where(tangents > threshold, tangents, 0.0)
    for j in np.flatnonzero(same) + 1:  # in order: a run of equal segments snaps to its first
        if abs(snapped[j] - snapped[j - 1]) <= threshold:
            snapped[j] = snapped[j - 1]
    previous = np.zeros(len(knots))
    previous[1:][same] = snapped[:-1][same]
    stiffness = snapped - previous
    keep = stiffness != 0.0
    ridges = tuple(tuple(directions[j].tolist()) + (float(knots[j]), float(stiffness[j])) for j in np.flatnonzero(keep))
    return RidgeMembrane((0.0, 0.0, 0.0, 0.0), ridges)

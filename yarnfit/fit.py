"""Weighted least-squares fit of an orthotropic shell to yarn-level energy densities: a linear
(StVK) model, and a strain-stiffening membrane (:class:`~yarnfit.shell.RidgeMembrane`) fitted
from the same samples (:mod:`yarnfit.ridge_fit`).

Input: samples (:class:`~yarnfit.samples.SampleResult`), each a prescribed surface deformation (first and second fundamental forms
``I``, ``II``) with the homogenized yarn-level energy per reference area ``Ū`` (J/m²). Output: a
:class:`ShellFit` holding the fitted :class:`~yarnfit.shell.ShellMaterial` and its quality report.

Conventions are those of :mod:`yarnfit.shell` (SI units, weft = t = first axis, warp = p = second
axis). The shell energy is linear in the parameter vector

    γ = (s00, s01, s11, s22, b00, b01, b11, b22)   (Pa),

so the fit is linear: ``W(γ; I, II) = D(I, II) γ`` with the design matrix rows (see
:func:`design_matrix`) ``h/2 (ε0², 2 ε0 ε1, ε1², ε2²)`` for the membrane and
``h³/2 (κ0², 2 κ0 κ1, κ1², κ2²)`` for bending.

Samples. Every sample (:class:`~yarnfit.samples.SampleResult`) belongs to one
:class:`~yarnfit.samples.Family` and is either a membrane sample (``II = 0``) or a bending sample
(``I = Id``), never both; each family pins one parameter (``Family.determines``: the pure stretches
s00 and s11, the biaxial stretch s01 against them, shear s22, the bends b00, b11, b22 and the saddle
b01). The optional uniaxial families (the transverse direction free, ``I = diag(λ², μ²)`` with μ
where the yarn-level energy is least) probe the free-width stiffness ``h (s00 − s01²/s11)``
directly (for a knit a small difference of large numbers that the pure families cannot resolve).

Because no parameter is shared between the membrane and the bending group, the two groups are
fitted (and their residual variances estimated) separately; their energies differ by orders of
magnitude and a pooled variance would be set by the membrane group alone.

Weights. ``w = exp(−½ (s/σ)²)``, Gaussian in the strain magnitude ``s``: ``‖E‖_F`` for membrane
samples, the surface strain ``‖II‖_F h/2`` for bending samples. ``σ`` is the caller's
``weight_width`` (dimensionless strain) or half the largest ``s`` of the group, so the fit favours
the small-strain behaviour the StVK model is meant to capture.

The strain-stiffening membrane (``membrane="nonlinear"``, the default) is fitted from the same
membrane samples by :func:`yarnfit.ridge_fit.fit_ridge_membrane`; ``S`` stays the linear fit's.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, lsq_linear

from .checks import real_number
from .jsonfile import finite_or_none
from .ridge_fit import fit_ridge_membrane
from .samples import (BENDING_FAMILIES, FAMILIES, MEMBRANE_FAMILIES, OTHER_BIAS_FAMILIES, UNIAXIAL_FAMILIES, Group,
                      SampleResult)
from .shell import (
    BENDING_PARAMETERS,
    MEMBRANE_PARAMETERS,
    PARAMETER_NAMES,
    SIGNED_BENDING_PARAMETERS,
    ShellMaterial,
    SignedBending,
    bending_strain,
    membrane_strain,
)

__all__ = [
    "IndefiniteFitError",
    "MODELS",
    "ShellFit",
    "design_matrix",
    "fit_residual_jacobian",
    "fit_shell",
    "sample_strain",
    "sample_weights",
    "shell_energy_of",
    "weighted_residuals",
]

# "full" fits all eight parameters; "paper" fixes b01 = 0 (the paper's model).
MODELS = ("full", "paper")
# The membrane of the fitted material: "nonlinear" (the strain-stiffening RidgeMembrane; S stays
# the linear fit) or "linear" (the paper's StVK, the Gaussian-weighted fit).
MEMBRANE_MODELS = ("nonlinear", "linear")
# The bending of the fitted material: "signed" (SignedBending: b00 and b11 one value per sign of the
# curvature; B stays the symmetric fit) or "symmetric" (B, the paper's quadratic).
BENDING_MODELS = ("signed", "symmetric")
# Lower bound of a diagonal stiffness (s00, s11, s22, b00, b11, b22) relative to the largest
# diagonal of its group in the unbounded fit. Positive, so a fitted material stays strictly positive
# definite; far below any physical anisotropy ratio (< 1e4), so it never binds a real stiffness;
# far above the round-off of the unbounded solution (~1e-15 relative), so a stiffness the data put
# at zero lands on the floor and is reported in ShellFit.active_bounds instead of as noise.
DIAGONAL_FLOOR_REL = 1e-12
# Largest |coupling| / sqrt(product of its diagonals), |s01|/sqrt(s00 s11) and |b01|/sqrt(b00 b11),
# a fit may return. The eigenvalues of the normalised block [[1, rho], [rho, 1]] are 1 +- rho, so
# at this bound the block's softest mode keeps 1 % of the geometric mean stiffness: strictly
# positive definite, and a stiffness matrix the shell solver can factor (condition <= 200 within
# the block). A knit's loops trade course for wale length (biaxial energy near the rank-one limit)
# and jersey bends one way far more easily than the other, so their yarn-level energies can ask
# for |rho| > 1, which no quadratic shell has; the fit then ends on this bound and says so.
COUPLING_LIMIT = 0.99
# Default width of the Gaussian weights as a fraction of the group's largest sample strain. An
# energy residual grows as strain², so a sample's pull on the fit goes as w s⁴ = s⁴ exp(−s²/2σ²),
# largest at s = 2σ: a quarter puts it at the middle of the sampled range, favouring small strains
# as the paper asks; half would let the largest (most nonlinear) samples dominate.
WEIGHT_WIDTH_FRACTION = 0.25
# Stopping tolerances of the coupling-bounded solve (relative step, cost change and gradient, in
# unit-scaled columns): at round-off, so the constrained optimum is as exact as the linear one; a
# problem of at most 5 unknowns converges in tens of evaluations, the limit only stops a runaway.
BOUNDED_SOLVE_TOLERANCE = 1e-15
BOUNDED_SOLVE_EVALUATIONS = 10000
# A diagonal the signed bending's bounded solve ends within this fraction of its floor sits on it:
# the solve's values are sums u² + p whose round-off puts them a few ulps above it.
FLOOR_ROUNDOFF = 1e-6

_DIAGONAL = ("s00", "s11", "s22", "b00", "b11", "b22", "b00_pos", "b00_neg", "b11_pos", "b11_neg")
# The residual-stress terms per group (see ShellFit.residual_stress).
RESIDUAL_STRESS_NAMES = {"membrane": ("n0", "n1", "n2"), "bending": ("m0", "m1", "m2")}
_ALL_RESIDUAL = RESIDUAL_STRESS_NAMES["membrane"] + RESIDUAL_STRESS_NAMES["bending"]
_GROUPS = ((Group.MEMBRANE, MEMBRANE_FAMILIES, MEMBRANE_PARAMETERS), (Group.BENDING, BENDING_FAMILIES, BENDING_PARAMETERS))
# Each group's coupled block: (diagonal, coupling, diagonal).
_COUPLINGS = {"membrane": ("s00", "s01", "s11"), "bending": ("b00", "b01", "b11")}
# The sample family that determines each parameter (named in notes and errors).
_FAMILY_OF = {family.determines: family for family in FAMILIES if family.determines is not None}
_FAMILY_OF.update({f"{name}_{side}": _FAMILY_OF[name] for name in ("b00", "b11") for side in ("pos", "neg")})


class IndefiniteFitError(ValueError):
    """The least-squares optimum is not positive definite.

    Attributes:
        family: the sample family whose energies determine the offending coupling
            (``Family.BIAXIAL_STRETCH`` for s01, ``Family.SADDLE_BEND`` for b01).
        parameters: the fitted parameters (Pa) by name.
    """

    def __init__(self, message: str, family: str, parameters: dict[str, float]) -> None:
        super().__init__(message)
        self.family = family
        self.parameters = parameters


@dataclass(frozen=True, eq=False)
class ShellFit:
    """Result of :func:`fit_shell`.

    Attributes:
        material: the fitted material, with the thickness given to the fit: for ``membrane``
            "nonlinear" with its strain-stiffening membrane (``material.nonlinear``, ``None`` if
            its fit failed: see ``notes``) and ``S`` the linear fit; for "linear" the linear fit;
            for ``bending`` "signed" with its signed bending (``material.signed_bending``) and
            ``B`` the symmetric fit.
        model: ``"full"`` or ``"paper"``.
        membrane: ``"nonlinear"`` or ``"linear"``.
        bending: ``"signed"`` or ``"symmetric"``: what the material carries.
        signed_fit: the signed bending fitted to the bends (``None`` when not asked for or not
            determined), which the material carries unless a stiffness of it ended on its floor
            where the symmetric fit's did not (``notes`` say so, with both models' bend R²).
        linear: the linear (StVK) fit from the same samples, with the symmetric bending.
        linear_families: per family statistics of ``linear`` (as ``families``) over the samples it
            was fitted to: the compression samples left out (:attr:`~yarnfit.samples.SampleSpec.compressed`).
        parameters: fitted stiffnesses (Pa) by name, all eight (b01 = 0 for the paper model): the
            linear fit's (the material's ``S`` and ``B``).
        std_error: standard errors (Pa) by name (the signed bending's six too, when fitted); 0 for
            a parameter the model fixes, NaN for a group with no more samples than parameters.
        families: per family ``{"r2": float, "relative_rms": float, "samples": int}`` of the
            material, unweighted, over the used samples (see :func:`fit_shell` for the edge cases).
        active_bounds: names of diagonal stiffnesses that ended on their positive floor, of
            couplings (s01, b01) held at zero because one of their diagonals did (a direction that
            carries no energy has no coupling to identify; positive definiteness then requires it
            to vanish, and the coupled family's data only shows model error), and of couplings at
            the positive-definite bound ``coupling_limit``.
        notes: one sentence per active bound: which bound, and which sample family asked for it.
        coupling_limit: the bound ρ_max on the couplings, or ``None`` (unbounded).
        excluded: the samples left out because they did not converge.
        used: the samples fitted, in input order.
        weights: ``(len(used),)`` least-squares weights of the linear fit, aligned with ``used``.
        weight_widths: σ (dimensionless strain) per group, ``{"membrane": σ, "bending": σ}``.
        fitted_energy: ``(len(used),)`` the material's energy density (J/m²) at the used samples.
        strain_range: per nonlinear direction (``s00``, ``s11``, ``s22``) the least and largest
            Voigt strain of the used membrane samples ``[lo, hi]``: where the ridges were fitted
            (beyond it each ray keeps its last tangent).
        reference_energy: Ū of the undeformed samples (J/m², their mean; 0 without one): the
            relaxed repeat's own energy, which every membrane sample's Ū includes.
        bending_reference_energy: Ū of the unbent bending samples (J/m², their mean; the
            ``reference_energy`` without one): the repeat's energy at zero membrane force
            (:func:`~yarnfit.samples.free_rest_sample`), the bends' reference, as they are
            solved at zero membrane force too.
        residual_stress: what the repeat carries at rest (0 without an undeformed sample):
            ``n0 n1 n2`` (N/m) along ε0, ε1, ε2, the membrane terms linear in the strain, fitted
            with the stiffening membrane and left out of the shell; ``m0 m1 m2`` (N, moment per
            width) along κ0, κ1, κ2, reported only (:func:`_residual_moments`).
    """

    material: ShellMaterial
    model: str
    parameters: dict[str, float]
    std_error: dict[str, float]
    families: dict[str, dict]
    active_bounds: list[str]
    excluded: list[SampleResult]
    used: list[SampleResult]
    weights: np.ndarray
    weight_widths: dict[str, float]
    fitted_energy: np.ndarray = field(repr=False)
    linear: ShellMaterial
    linear_families: dict[str, dict]
    membrane: str = "nonlinear"
    bending: str = "symmetric"
    signed_fit: SignedBending | None = None
    strain_range: dict[str, list[float]] = field(default_factory=dict)
    reference_energy: float = 0.0
    residual_stress: dict[str, float] = field(default_factory=dict)
    bending_reference_energy: float | None = None
    notes: list[str] = field(default_factory=list)
    coupling_limit: float | None = COUPLING_LIMIT

    def shell_energy(self, samples: Sequence[SampleResult]) -> np.ndarray:
        """``(n,)`` the part of each sample's Ū the shell represents (J/m²): Ū less the rest
        energy and the membrane's residual-stress terms (NaN stays NaN)."""
        return shell_energy_of(samples, self.reference_energy, self.residual_stress, self.bending_reference_energy)

    @property
    def bending_reference(self) -> float:
        """The bends' rest energy (J/m²): ``bending_reference_energy``, else ``reference_energy``."""
        return self.reference_energy if self.bending_reference_energy is None else self.bending_reference_energy

    def quality_dict(self) -> dict:
        """Everything but the material as plain JSON data (str, float, int, list, dict).

        Non-finite numbers (an r2 of −inf, NaN standard errors) are written as ``None`` so that the
        material file stays strict JSON.
        """
        def sample_dict(sample: SampleResult) -> dict:
            return {
                "family": sample.family,
                "parameter": sample.parameter,
                "I": sample.I.tolist(),
                "II_per_m": sample.II.tolist(),
                "energy_density_j_per_m2": finite_or_none(sample.energy_density),
                "residual": finite_or_none(sample.worst_residual),
            }

        used = []
        for sample, weight, fitted in zip(self.used, self.weights, self.fitted_energy):
            entry = sample_dict(sample)
            entry["weight"] = float(weight)
            entry["fitted_energy_density_j_per_m2"] = float(fitted)
            used.append(entry)
        return {
            "model": self.model,
            "membrane": self.membrane,
            "bending": self.bending,
            "parameters_pa": {k: float(v) for k, v in self.parameters.items()},
            "std_error_pa": {k: finite_or_none(v) for k, v in self.std_error.items()},
            "families": _json_families(self.families),
            "linear": {
                "parameters_pa": {k: float(v) for k, v in self.linear.parameters.items()},
                "families": _json_families(self.linear_families),
            },
            "strain_range": {k: [float(v) for v in r] for k, r in self.strain_range.items()},
            "reference_energy_j_per_m2": float(self.reference_energy),
            "bending_reference_energy_j_per_m2": float(self.bending_reference),
            "residual_stress": {
                "membrane_n_per_m": {k: float(self.residual_stress.get(k, 0.0)) for k in RESIDUAL_STRESS_NAMES["membrane"]},
                "bending_n": {k: float(self.residual_stress.get(k, 0.0)) for k in RESIDUAL_STRESS_NAMES["bending"]},
            },
            "active_bounds": list(self.active_bounds),
            "notes": list(self.notes),
            "coupling_limit": self.coupling_limit,
            "weight_widths": {k: float(v) for k, v in self.weight_widths.items()},
            "used": used,
            "excluded": [sample_dict(sample) for sample in self.excluded],
        }


def shell_energy_of(samples: Sequence[SampleResult], reference_energy: float = 0.0,
                    residual_stress: dict[str, float] | None = None,
                    bending_reference_energy: float | None = None) -> np.ndarray:
    """``(n,)`` the part of each sample's Ū the shell represents (J/m²): Ū less the rest energy
    (J/m²: ``reference_energy`` of a membrane sample, ``bending_reference_energy`` of a bend,
    ``reference_energy`` if that is ``None``) and the membrane's residual-stress terms ``n · ε``
    (``residual_stress`` by name, ``n0 n1 n2`` in N/m; a missing one is 0, the bending moments are
    not fitted). NaN stays NaN. :meth:`ShellFit.shell_energy` with a fit's own values; a material
    file keeps them (:meth:`~yarnfit.material_file.MaterialFile.rest_state`)."""
    samples = _sample_list(samples)
    residual_stress = residual_stress or {}
    energy = np.array([s.energy_density for s in samples], dtype=np.float64)
    stress = np.array([residual_stress.get(n, 0.0) for n in RESIDUAL_STRESS_NAMES["membrane"]])
    return (energy - _rest_energies(samples, reference_energy, bending_reference_energy)
            - _residual_stress_columns(samples)[:, :3] @ stress)


def _rest_energies(samples: list[SampleResult], reference_energy: float,
                   bending_reference_energy: float | None) -> np.ndarray:
    """``(n,)`` each sample's rest energy (J/m², :func:`shell_energy_of`)."""
    bending = reference_energy if bending_reference_energy is None else bending_reference_energy
    return np.array([reference_energy if s.is_membrane else bending for s in samples], dtype=np.float64)


def design_matrix(samples: Sequence[SampleResult], thickness: float) -> np.ndarray:
    """``dW/dγ`` for each sample, ``(n, 8)``, columns in :data:`~yarnfit.shell.PARAMETER_NAMES` order.

    Rows: ``h/2 (ε0², 2 ε0 ε1, ε1², ε2²)`` in the membrane columns and
    ``h³/2 (κ0², 2 κ0 κ1, κ1², κ2²)`` in the bending columns (J/m² per Pa), with ε and κ the Voigt
    strains of :mod:`yarnfit.shell`.
    """
    h = _thickness(thickness)
    samples = _sample_list(samples)
    eps = membrane_strain(np.stack([s.I for s in samples]))
    kap = bending_strain(np.stack([s.II for s in samples]))
    D = np.empty((len(samples), len(PARAMETER_NAMES)))
    for offset, v, scale in ((0, eps, 0.5 * h), (4, kap, 0.5 * h**3)):
        D[:, offset + 0] = scale * v[:, 0] ** 2
        D[:, offset + 1] = scale * 2.0 * v[:, 0] * v[:, 1]
        D[:, offset + 2] = scale * v[:, 1] ** 2
        D[:, offset + 3] = scale * v[:, 2] ** 2
    return D


def sample_strain(sample: SampleResult, thickness: float) -> float:
    """Strain magnitude used for weighting (dimensionless).

    ``‖E‖_F`` with ``E = ½(I − Id)`` for a membrane sample; ``‖II‖_F h/2``, the surface strain of the
    shell, for a bending sample.
    """
    h = _thickness(thickness)
    if sample.is_membrane:
        return float(np.linalg.norm(0.5 * (sample.I - np.eye(2))))
    return float(np.linalg.norm(sample.II) * 0.5 * h)


def sample_weights(
    samples: Sequence[SampleResult], thickness: float, weight_width: float | None = None
) -> tuple[np.ndarray, dict[str, float]]:
    """Least-squares weights ``w = exp(−½ (s/σ)²)`` and the widths σ used.

    Args:
        samples: the samples to weight (for a fit: the converged ones).
        thickness: shell thickness h (m).
        weight_width: σ (dimensionless strain) for both groups; ``None`` takes WEIGHT_WIDTH_FRACTION
            of the largest :func:`sample_strain` of each group separately.

    Returns:
        ``(w, widths)``: ``w`` ``(n,)`` in (0, 1], ``widths`` σ by group name for the groups present.

    Raises:
        ValueError: ``weight_width`` not finite and > 0, or (for ``None``) a group whose samples all
            have zero strain.
    """
    samples = _sample_list(samples)
    if weight_width is not None:
        weight_width = real_number(weight_width, "weight_width")
        if not (math.isfinite(weight_width) and weight_width > 0.0):
            raise ValueError(f"weight_width must be finite and > 0 (dimensionless strain), got {weight_width!r}")
    strain = np.array([sample_strain(s, thickness) for s in samples])
    membrane = np.array([s.is_membrane for s in samples], dtype=bool)
    weights = np.empty(len(samples))
    widths = {}
    for group, mask in (("membrane", membrane), ("bending", ~membrane)):
        if not np.any(mask):
            continue
        sigma = weight_width if weight_width is not None else WEIGHT_WIDTH_FRACTION * float(np.max(strain[mask]))
        if sigma == 0.0:
            raise ValueError(f"all {group} samples have zero strain: they cannot determine any {group} stiffness")
        weights[mask] = np.exp(-0.5 * (strain[mask] / sigma) ** 2)
        widths[group] = sigma
    return weights, widths


def weighted_residuals(
    params: Sequence[float], samples: Sequence[SampleResult], thickness: float, weights: np.ndarray
) -> np.ndarray:
    """``√w (W_shell(γ; I, II) − Ū)`` (J/m², w dimensionless), ``(n,)``.

    Evaluated through :meth:`ShellMaterial.energy_density`, independently of :func:`design_matrix`,
    so a finite-difference check of :func:`fit_residual_jacobian` tests the design matrix.

    Args:
        params: γ ``(8,)`` (Pa) in :data:`~yarnfit.shell.PARAMETER_NAMES` order; need not be
            positive definite.
    """
    samples = _sample_list(samples)
    gamma = _params(params)
    material = ShellMaterial(_thickness(thickness), **dict(zip(PARAMETER_NAMES, gamma)))
    W = material.energy_density(np.stack([s.I for s in samples]), np.stack([s.II for s in samples]))
    target = np.array([s.energy_density for s in samples])
    return np.sqrt(_weights(weights, len(samples))) * (W - target)


def fit_residual_jacobian(
    params: Sequence[float], samples: Sequence[SampleResult], thickness: float, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted residuals ``(n,)`` and their Jacobian ``d r/d γ = √w D`` ``(n, 8)`` at γ = ``params``."""
    r = weighted_residuals(params, samples, thickness, weights)
    J = np.sqrt(_weights(weights, len(r)))[:, None] * design_matrix(samples, thickness)
    return r, J


# A uniaxial (free-width) sample whose rods store at least this share of Ū in centreline stretch
# and shear is reported: its structure did not give way, its yarns were pulled. Measured at 2 %
# (session 28): pulls that give way by bending store 0.5–8 % there (every jersey's course-wise
# pull, cotton jersey's wale-wise one, the twill's weft), jammed ones 83–98 % (wool and polyester
# jersey along the wales, where four rigid yarn diameters already fill a wale; the twill's warp).
STRETCH_DOMINATED_SHARE = 0.5


def stretch_dominated_notes(samples: Sequence[SampleResult]) -> list[str]:
    """One note per uniaxial sample that pulled its yarns rather than bending them (stretch share
    at least :data:`STRETCH_DOMINATED_SHARE`; samples without a known share are skipped)."""
    notes = []
    for sample in samples:
        axis = sample.family.uniaxial_axis
        if axis is None or not sample.converged or not sample.stretch_share >= STRETCH_DOMINATED_SHARE:
            continue
        across = float(np.sqrt(sample.I[1 - axis, 1 - axis]))
        notes.append(f"the {sample.family} sample at {100 * sample.parameter:.3g} % stores "
                     f"{100 * sample.stretch_share:.0f} % of its energy in stretching the yarn (width {across:.3f}): "
                     f"the structure is jammed across the pull and the yarn itself is pulled, so the fitted "
                     f"{'weft' if axis == 0 else 'warp'} stiffness is the yarn's (rigid yarn cross-sections: "
                     f"docs/design.md §4)")
    return notes


def fit_shell(
    samples: Iterable[SampleResult],
    thickness: float,
    model: str = "full",
    weight_width: float | None = None,
    coupling_limit: float | None = COUPLING_LIMIT,
    membrane: str = "nonlinear",
    residual_stress: bool = False,
    bending: str = "signed",
    even_shear: bool = True,
) -> ShellFit:
    """Fit an orthotropic shell to yarn-level energies: the linear (StVK) model by weighted linear
    least squares, and (``membrane="nonlinear"``) the strain-stiffening membrane (module docstring).

    Solves ``min Σ w_i (W_shell(γ; I_i, II_i) − Ū_i)²`` over the converged samples, each group
    (membrane, bending) on its own, with the diagonal stiffnesses bounded below by
    :data:`DIAGONAL_FLOOR_REL` × the largest diagonal of the group's unbounded fit and the couplings
    by ``|s01| ≤ coupling_limit √(s00 s11)``, ``|b01| ≤ coupling_limit √(b00 b11)``.

    Args:
        samples: homogenized samples; non-converged ones are excluded and listed in the result.
        thickness: shell thickness h (m).
        model: ``"full"`` (fits b01, needs ``Family.SADDLE_BEND`` samples) or ``"paper"`` (b01 = 0).
        weight_width: σ of the Gaussian weights (dimensionless strain), or ``None``; see
            :func:`sample_weights`.
        coupling_limit: ρ_max in (0, 1), or ``None`` to fit the couplings unbounded and raise
            :class:`IndefiniteFitError` when the optimum is not positive definite.
        membrane: ``"nonlinear"`` (the material carries the stiffening membrane) or ``"linear"``.
        bending: ``"signed"`` (the material carries a :class:`~yarnfit.shell.SignedBending` fitted
            to the same bends, :func:`_fit_signed_bending`) or ``"symmetric"``.
        residual_stress: with an undeformed sample, also fit the membrane's terms linear in the
            strain (``ShellFit.residual_stress`` n0 n1 n2) and leave them out of the shell. Off by
            default: a relaxed repeat's rest state is its relaxed shape, force-free by construction
            (``yarnfit.relax``), and fitted terms only took up what the membrane model missed
            (cotton twill: −19.6 / 35.9 N/m, which put its shear tangent at 2e-4 Pa once the
            compression-side terms came in, and the shell 20x off its own ±0.1 % shear samples).
        even_shear: the stiffening membrane's rays with a shear part share one tangent with their
            mirrors in the shear (:func:`yarnfit.ridge_fit._shear_ties`): the membrane is even in the shear,
            orthotropic. ``False`` lets a structure whose twill or satin line shears it stiffer one
            way keep that (each ray fitted on its own); its samples then want pulls along both
            biases (``bias_uniaxial`` and ``negative_bias_uniaxial``), or the side without them is
            set by the pure shear alone.

    Returns:
        the :class:`ShellFit`. Per family: ``r2 = 1 − SS_res/SS_tot`` (unweighted, ``SS_tot`` about
        the family mean) and ``relative_rms = RMS(W − Ū)/RMS(Ū)``. When ``SS_tot = 0`` (one sample,
        or all energies equal) r2 is 1.0 if ``SS_res = 0`` and −inf otherwise; when ``RMS(Ū) = 0``
        relative_rms is 0.0 if the residuals are all zero and +inf otherwise. Standard errors:
        covariance ``σ̂² (Jᵀ W J)⁺`` per group, ``σ̂² = Σ w r² / (n − p)``.

    Raises:
        ValueError: bad thickness, model or weight width; a required family without converged
            samples (named); a parameter the samples do not determine (named).
        IndefiniteFitError: only with ``coupling_limit=None``: ``s01² ≥ s00 s11`` (family
            ``Family.BIAXIAL_STRETCH``) or ``b01² ≥ b00 b11`` (``Family.SADDLE_BEND``) at the optimum.
    """
    h = _thickness(thickness)
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    if membrane not in MEMBRANE_MODELS:
        raise ValueError(f"membrane must be one of {', '.join(MEMBRANE_MODELS)}, got {membrane!r}")
    if bending not in BENDING_MODELS:
        raise ValueError(f"bending must be one of {', '.join(BENDING_MODELS)}, got {bending!r}")
    if coupling_limit is not None:
        coupling_limit = real_number(coupling_limit, "coupling_limit")
        if not 0.0 < coupling_limit < 1.0:
            raise ValueError(f"coupling_limit must be in (0, 1) (or None for no bound), got {coupling_limit!r}")
    samples = _sample_list(samples)
    used = [s for s in samples if s.converged]
    excluded = [s for s in samples if not s.converged]

    # The paper's model fixes b01 = 0, so it needs no family that determines b01.
    required = tuple(f for f in FAMILIES if not f.optional and (model == "full" or f.determines != "b01"))
    missing = []
    for family in required:
        if not any(s.family == family for s in used):
            dropped = sum(s.family == family for s in excluded)
            missing.append(f"{family} ({dropped} excluded as not converged)" if dropped else family)
    if missing:
        raise ValueError(
            f"no usable (converged) samples for families: {', '.join(missing)}; model {model!r} needs "
            f"{', '.join(required)}"
        )

    # The energy references and the residual stress (module docstring): the undeformed samples'
    # mean energy is subtracted, the membrane's from the membrane samples and the unbent bending
    # samples' (at zero membrane force) from the bends, and each group gains the terms linear in
    # its strains.
    target = np.array([s.energy_density for s in used])
    undeformed = np.array([_is_undeformed(s) for s in used], dtype=bool)
    membrane_rows = np.array([s.is_membrane for s in used], dtype=bool)
    # The linear (orthotropic) model is even in the shear: it cannot tell a woven's two biases apart,
    # and fitted to both the cotton twill's s22 went to its floor (its −45° pulls, 4-18 times its
    # +45° ones, asked more of the normal strains than the samples hold, session 47). It keeps the
    # design's first bias, as before the other was sampled; the stiffening membrane takes both.
    # Nor can it be stiffer one way than the other: at 0.1 % a woven's biaxial compression stores
    # ~1/50 of its tension's energy, a knit's weft from 1/100 (cotton jersey) to 15 times (wool
    # jersey) its tension's, and fitted to both the linear model took a compromise (wool jersey's
    # s00 29.3e6 → 12.2e6 Pa). It is the small-strain tangent in tension; the stiffening membrane
    # takes the compression samples (samples.SampleRanges).
    pulled = np.array([not s.spec.compressed for s in used], dtype=bool)
    linear_rows = np.array([s.family not in OTHER_BIAS_FAMILIES for s in used], dtype=bool) & pulled
    reference_energy = float(np.mean(target[undeformed & membrane_rows])) if np.any(undeformed & membrane_rows) else 0.0
    bending_reference_energy = (float(np.mean(target[undeformed & ~membrane_rows]))
                                if np.any(undeformed & ~membrane_rows) else None)
    rest_energy = _rest_energies(used, reference_energy, bending_reference_energy)
    relative = target - rest_energy
    weights, widths = sample_weights(used, h, weight_width)
    D = design_matrix(used, h)
    linear_terms = _residual_stress_columns(used)

    parameters = dict.fromkeys(PARAMETER_NAMES, 0.0)
    std_error = dict.fromkeys(PARAMETER_NAMES, 0.0)
    active: list[str] = []
    notes: list[str] = []
    rest_stress = dict.fromkeys(_ALL_RESIDUAL, 0.0)
    reference = bool(np.any(undeformed & membrane_rows))

    def linear_group(group, families, names, energies, residual, without=()):
        """The linear fit of one group (with its residual-stress terms if ``residual``), leaving
        out the samples of the families ``without``. A diagonal on its floor that one uniaxial
        family put there (the fit without it is off the floor) is fitted without that family, and
        a note says so; the R² are still over every sample."""
        rows = (membrane_rows if group == "membrane" else ~membrane_rows) & ~undeformed & linear_rows
        rows &= np.array([s.family not in without for s in used], dtype=bool)
        offset = 0 if group == "membrane" else 3
        extra = list(RESIDUAL_STRESS_NAMES[group]) if residual else []
        group_notes = []
        if extra and np.linalg.matrix_rank(np.hstack([D[rows][:, [PARAMETER_NAMES.index(n) for n in names]],
                                                      linear_terms[rows, offset:offset + 3]])) < len(names) + 3:
            group_notes.append(f"the {group} samples cannot separate a residual stress from the stiffnesses: "
                               f"fitted without")
            extra = []
        stress = {}

        def fit(free, limit):
            cols = [PARAMETER_NAMES.index(n) for n in free]
            block = D[np.ix_(rows, cols)]
            if extra:
                block = np.hstack([block, linear_terms[rows, offset:offset + 3]])
            values, errors, at_bound, ratio = _fit_group(group, families, free + extra, block, energies[rows],
                                                         weights[rows], _COUPLINGS[group], limit)
            for n in extra:
                stress[n] = values.pop(n)
                errors.pop(n)
            return values, errors, at_bound, ratio

        free = [n for n in names if not (model == "paper" and n == "b01")]
        d0, off, d1 = _COUPLINGS[group]
        limit = coupling_limit if off in free else None
        values, errors, at_bound, ratio = fit(free, limit)
        floors = [n for n in at_bound if n in _DIAGONAL]
        if floors and not without:
            # A uniaxial sample's free strains are the yarns' answer, not the linear membrane's: a
            # woven's bias pull contracts both thread directions, which its yarns give freely (crimp)
            # and a linear membrane charges at the stretch stiffness (the twill at 2 %: 0.064 J/m² for
            # a pull whose whole energy is 5e-4), so the fit bought it back with a shear on its floor.
            present = {used[i].family for i in np.flatnonzero(rows)}
            for family in (f for f in UNIAXIAL_FAMILIES if f in present):
                refit = linear_group(group, families, names, energies, residual, (family,))
                refit_values, refit_errors, refit_bound, refit_notes, refit_stress = refit
                if not set(floors) & set(refit_bound):
                    note = (f"fitted without the {family} samples: with them {', '.join(floors)} went to the "
                            f"positive floor (the linear membrane cannot follow their free contraction; its R² on "
                            f"them says by how much)")
                    return refit_values, refit_errors, refit_bound, [note] + refit_notes, refit_stress
        if off in free and {d0, d1} & set(floors):
            # A direction that carries no energy has nothing to couple to: refit with the coupling 0.
            free = [n for n in free if n != off]
            values, errors, at_bound, _ = fit(free, None)
            floors = list(at_bound)
            at_bound = floors + [off]
        group_notes += [f"{n} at its positive floor: the {_FAMILY_OF[n]} energies carry no {n} stiffness"
                        for n in floors]
        if off in at_bound and off not in values:
            group_notes.append(f"{off} held at 0: {' and '.join(n for n in (d0, d1) if n in floors)} at the positive "
                               f"floor")
        elif off in at_bound:
            group_notes.append(f"{off} at the positive-definite bound |{off}| = {coupling_limit:g} √({d0}·{d1}): the "
                               f"{_FAMILY_OF[off]} energies ask for {off}/√({d0}·{d1}) = {ratio:.3g}, which no "
                               f"positive-definite shell has (the unbounded fit is indefinite)")
        return values, errors, at_bound, group_notes, stress

    # Bending: the linear model, without residual moments. A quadratic bending fit cannot tell a
    # residual moment from a bend that is stiffer one way than the other (a jersey's, 8x): fitted
    # with it, cotton jersey's weft-bend asymmetry came out as a moment of −0.016 N that ruined its
    # bias bends (R² −4.7); what the small curvatures say about it is reported instead.
    (_, bending_families, bending_names), (_, membrane_families, membrane_names) = _GROUPS[1], _GROUPS[0]
    values, errors, at_bound, group_notes, _ = linear_group("bending", bending_families, bending_names, relative,
                                                            False)
    parameters.update(values), std_error.update(errors)
    if reference:
        rest_stress.update(_residual_moments(used, relative))
    bending_active, bending_notes = at_bound, group_notes
    signed, unused_signed = None, None
    if bending == "signed":
        bends = ~membrane_rows & ~undeformed
        signed, errors, at_bound, group_notes = _fit_signed_bending(
            [s for s, bend in zip(used, bends) if bend], relative[bends], weights[bends], h, model == "full",
            coupling_limit)
        # A stiffness the signed fit puts on its floor where the symmetric fit's is not leaves a
        # bending mode without stiffness (the jerseys' b22: their bias bends softer than their
        # weft and warp bends' stiffer sides, which the convex signed bending cannot follow): the
        # material keeps the symmetric bending, and the notes say what the signed one fitted.
        floored = {n for n in at_bound if n != "b01"}
        lost = sorted(n for n in floored if n.split("_")[0] not in bending_active)
        if signed is None:
            bending_notes = bending_notes + group_notes
        elif lost:
            unused_signed, signed = signed, None
            bending_notes = bending_notes + [
                f"signed bending not used: its {', '.join(lost)} at the positive floor where the symmetric fit's "
                f"{', '.join(sorted({n.split('_')[0] for n in lost}))} is not (a bending mode without stiffness); "
                f"the material keeps the symmetric bending"]
        else:
            std_error.update(errors)
            bending_active = bending_active + at_bound
            bending_notes = [f"symmetric bending: {note}" for note in bending_notes] + group_notes
    # Membrane: a quadratic cannot tell a residual stress from the curvature of the energy (a
    # linear fibre's Green-strain softening came out as 200 N/m of it), so the stiffening model,
    # which follows the curve, measures the residual stress (when asked); the linear fit takes it
    # as given. Its first fit (no residual terms) gives the floors and the constrained solve's start.
    values, errors, at_bound, group_notes, _ = linear_group("membrane", membrane_families, membrane_names, relative,
                                                            False)
    start = ShellMaterial(h, **{**parameters, **values})
    stiffening_fit = None
    fit_stress = reference and residual_stress
    if membrane == "nonlinear" or fit_stress:
        membrane_used = [(s, e) for s, e, u in zip(used, relative, undeformed) if s.is_membrane and not u]
        stiffening_fit = fit_ridge_membrane(membrane_used, h, start,
                                            RESIDUAL_STRESS_NAMES["membrane"] if fit_stress else None, even_shear)
        rest_stress.update(stiffening_fit[3])
    if fit_stress:
        shifted = relative - linear_terms[:, :3] @ np.array([rest_stress[n] for n in RESIDUAL_STRESS_NAMES["membrane"]])
        values, errors, at_bound, group_notes, _ = linear_group("membrane", membrane_families, membrane_names, shifted,
                                                                False)
    parameters.update(values), std_error.update(errors)
    active = at_bound + bending_active
    if membrane == "nonlinear":  # the material's membrane is the stiffening one: say whose these are
        group_notes = [f"linear model: {note}" for note in group_notes]
    notes = group_notes + bending_notes

    for d0, off, d1 in _COUPLINGS.values():
        family = _FAMILY_OF[off]
        p0, p01, p1 = parameters[d0], parameters[off], parameters[d1]
        if p01 * p01 >= p0 * p1:
            floors = [n for n in (d0, d1) if n in active]
            note = f"; {', '.join(floors)} at the positive floor" if floors else ""
            raise IndefiniteFitError(
                f"fitted {d0}/{off}/{d1} block is not positive definite: {off}² = {p01 * p01:.6g} >= "
                f"{d0}·{d1} = {p0 * p1:.6g} ({d0} = {p0:.6g} Pa, {off} = {p01:.6g} Pa, {d1} = {p1:.6g} Pa{note}); "
                f"the {family} energies are inconsistent with the uniaxial ones (check those samples)",
                family,
                dict(parameters),
            )

    linear = ShellMaterial(h, **parameters)

    def predicted(material: ShellMaterial, stress: dict[str, float]) -> np.ndarray:
        """The fit's prediction of each used sample's Ū: the shell, the reference, the residual stress."""
        shell = material.energy_density(np.stack([s.I for s in used]), np.stack([s.II for s in used]))
        membrane_stress = np.array([stress[n] for n in RESIDUAL_STRESS_NAMES["membrane"]])
        return shell + rest_energy + linear_terms[:, :3] @ membrane_stress

    # Over the samples the linear model was fitted to: it is even in the strain's sign, and the
    # compression samples' misfit is the stiffening membrane's to take.
    linear_families = _family_statistics(used, predicted(linear, rest_stress), target, pulled)
    if unused_signed is not None:
        tried = _family_statistics(used, predicted(ShellMaterial(h, **parameters, signed_bending=unused_signed),
                                                   rest_stress), target)
        notes.append("the signed bending it fitted: " + ", ".join(
            f"{name} = {value:.4g} Pa" for name, value in unused_signed.parameters.items()) + "; bend R² (signed / "
            "symmetric) " + ", ".join(f"{family} {tried[family]['r2']:.3f} / {linear_families[family]['r2']:.3f}"
                                      for family in BENDING_FAMILIES if tried.get(family, {}).get("samples")))
    material, strain_range = ShellMaterial(h, **parameters, signed_bending=signed), {}
    if membrane == "nonlinear":
        stiffening, membrane_notes, strain_range, _ = stiffening_fit
        material = ShellMaterial(h, **parameters, nonlinear=stiffening, signed_bending=signed)
        notes += membrane_notes
    notes += stretch_dominated_notes(used)
    fitted = predicted(material, rest_stress)
    return ShellFit(
        material=material,
        model=model,
        membrane=membrane,
        bending="signed" if signed is not None else "symmetric",
        signed_fit=signed if signed is not None else unused_signed,
        parameters=parameters,
        std_error=std_error,
        families=_family_statistics(used, fitted, target),
        active_bounds=active,
        excluded=excluded,
        used=used,
        weights=weights,
        weight_widths=widths,
        fitted_energy=fitted,
        linear=linear,
        linear_families=linear_families,
        strain_range=strain_range,
        reference_energy=reference_energy,
        residual_stress=rest_stress,
        bending_reference_energy=bending_reference_energy,
        notes=notes,
        coupling_limit=coupling_limit,
    )


def signed_design_matrix(samples: Sequence[SampleResult], thickness: float) -> np.ndarray:
    """``dW/dγ`` of the signed bending (:class:`~yarnfit.shell.SignedBending`) for each sample,
    ``(n, 6)``, columns in :data:`~yarnfit.shell.SIGNED_BENDING_PARAMETERS` order:
    ``h³/2 (κ0₊², κ0₋², 2 κ0 κ1, κ1₊², κ1₋², κ2²)`` (J/m² per Pa), ``κ₊ = max(κ, 0)``,
    ``κ₋ = min(κ, 0)``."""
    h = _thickness(thickness)
    kap = bending_strain(np.stack([s.II for s in _sample_list(samples)]))
    above, below = np.maximum(kap, 0.0), np.minimum(kap, 0.0)
    return 0.5 * h**3 * np.column_stack([above[:, 0]**2, below[:, 0]**2, 2.0 * kap[:, 0] * kap[:, 1],
                                         above[:, 1]**2, below[:, 1]**2, kap[:, 2]**2])


def _fit_signed_bending(bends: list[SampleResult], energies: np.ndarray, weights: np.ndarray, h: float,
                        coupled: bool, coupling_limit: float | None
                        ) -> tuple[SignedBending | None, dict[str, float], list[str], list[str]]:
    """The signed bending fitted to the ``bends`` (their ``energies`` relative to the unbent
    reference, J/m², and least-squares ``weights``), as the symmetric one is (:func:`_fit_group`:
    the same floors, rank test and standard errors), and convex: ``|b01| <= coupling_limit ·
    √(min(b00_pos, b00_neg) · min(b11_pos, b11_neg))`` (:func:`_signed_coupling_solve`; held at 0
    without ``coupled``: the paper's model). Returns ``(the bending, standard errors by name, names
    at a bound, notes)``; the bending is ``None`` (and the notes say why) when the bends do not
    strain every stiffness it has, or when its optimum is not convex and ``coupling_limit`` is
    ``None`` (unbounded couplings: the symmetric fit is then what is judged)."""
    D = signed_design_matrix(bends, h)
    names = list(SIGNED_BENDING_PARAMETERS)
    free = names if coupled else [n for n in names if n != "b01"]
    unsampled = [n for n, norm in zip(names, np.linalg.norm(np.sqrt(weights)[:, None] * D, axis=0))
                 if norm == 0.0 and n in free]
    if unsampled:
        return None, {}, [], [f"signed bending not fitted: no bend with weight strains {', '.join(unsampled)} "
                              f"(it needs weft and warp bends of both signs)"]
    families = tuple(sorted({s.family for s in bends}))
    columns = [names.index(n) for n in free]
    values, errors, at_bound, _ = _fit_group("signed bending", families, free, D[:, columns], energies, weights,
                                             ("b00_pos", "b01", "b11_pos"), None)
    values.setdefault("b01", 0.0), errors.setdefault("b01", 0.0)
    coupling_note = []
    result = SignedBending(**values)
    if coupled and not result.positive_definite:
        if coupling_limit is None:  # unbounded couplings (--strict): the symmetric fit is judged
            return None, {}, [], [f"signed bending not used: its unbounded optimum is not convex "
                                  f"({'; '.join(result.problems())}) and the couplings are not bounded"]
        # Unlike the symmetric fit, a diagonal at its floor does not put b01 at 0: the bounded
        # solve below is the convex problem's optimum, which holds the symmetric fit among its
        # candidates (equal sides), so it never fits the bends worse than the symmetric one.
        sw = np.sqrt(weights)
        floor = DIAGONAL_FLOOR_REL * max(values[n] for n in names if n != "b01")
        least = np.array([min(values["b00_pos"], values["b00_neg"]), values["b01"],
                          min(values["b11_pos"], values["b11_neg"])])
        ratio = _coupling_ratio(least, 0, 1, 2)
        values = _signed_coupling_solve(sw[:, None] * D, sw * energies, values, coupling_limit, floor)
        at_bound = [n for n in names if n != "b01" and values[n] <= floor] + ["b01"]
        coupling_note = [f"signed bending: b01 at the convexity bound |b01| = {coupling_limit:g} "
                         f"√(min(b00_pos, b00_neg)·min(b11_pos, b11_neg)): the saddle_bend energies ask for "
                         f"{ratio:.3g}, which no convex signed bending has"]
        result = SignedBending(**values)
    notes = [f"signed bending: {n} at its positive floor: the {_FAMILY_OF[n]} energies carry no {n} stiffness"
             for n in at_bound if n != "b01"] + coupling_note
    return result, {n: errors[n] for n in names}, at_bound, notes


def _signed_coupling_solve(A: np.ndarray, b: np.ndarray, start: dict[str, float], limit: float,
                           floor: float) -> dict[str, float]:
    """``min ‖A γ − b‖`` over the signed bending's six stiffnesses ``γ`` (Pa; ``A`` ``(n, 6)`` in
    :data:`~yarnfit.shell.SIGNED_BENDING_PARAMETERS` order) subject to every diagonal ``>= 0`` and
    ``|b01| <= limit √(min(b00_pos, b00_neg) · min(b11_pos, b11_neg))``, the diagonals at least
    ``floor`` (Pa; one that ends within round-off of it is put on it exactly).

    Solved in ``(u, p₊, p₋, v, q₊, q₋, ρ, w)`` (Pa and √Pa) with ``b00_± = u² + p_±``,
    ``b11_± = v² + q_±`` (``p, q >= 0``), ``b01 = ρ u v``, ``|ρ| <= limit``, ``b22 = w``: the feasible set of ``γ`` is an intersection of four convex cones (one per
    pair of sides) and the objective convex, so the local optimum this finds from ``start`` (the
    unbounded fit, its coupling put on the bound) is the global one."""
    scale = np.linalg.norm(A, axis=0)
    As = A / scale
    gamma0 = np.array([start[n] for n in SIGNED_BENDING_PARAMETERS])
    u, v = math.sqrt(max(min(gamma0[0], gamma0[1]), 0.0)), math.sqrt(max(min(gamma0[3], gamma0[4]), 0.0))

    def unpack(theta):
        u, p_pos, p_neg, v, q_pos, q_neg, rho, w = theta
        return np.array([u * u + p_pos, u * u + p_neg, rho * u * v, v * v + q_pos, v * v + q_neg, w])

    def residual(theta):
        return As @ (unpack(theta) * scale) - b

    def jacobian(theta):
        u, _, _, v, _, _, rho, _ = theta
        d = np.zeros((6, 8))  # d γ / d θ
        d[0, 0], d[0, 1] = 2.0 * u, 1.0
        d[1, 0], d[1, 2] = 2.0 * u, 1.0
        d[2, 0], d[2, 3], d[2, 6] = rho * v, rho * u, u * v
        d[3, 3], d[3, 4] = 2.0 * v, 1.0
        d[4, 3], d[4, 5] = 2.0 * v, 1.0
        d[5, 7] = 1.0
        return As @ (scale[:, None] * d)

    theta0 = np.array([u, gamma0[0] - u * u, gamma0[1] - u * u, v, gamma0[3] - v * v, gamma0[4] - v * v,
                       math.copysign(limit, gamma0[2]), max(gamma0[5], 0.0)])
    theta0[[1, 2, 4, 5]] = np.maximum(theta0[[1, 2, 4, 5]], 0.0)
    theta0[[0, 3]] = np.maximum(theta0[[0, 3]], math.sqrt(floor))
    theta0[7] = max(theta0[7], floor)
    low = np.array([math.sqrt(floor), 0.0, 0.0, math.sqrt(floor), 0.0, 0.0, -limit, floor])
    high = np.array([np.inf, np.inf, np.inf, np.inf, np.inf, np.inf, limit, np.inf])
    solution = least_squares(residual, theta0, jac=jacobian, bounds=(low, high), method="trf", x_scale="jac",
                             xtol=BOUNDED_SOLVE_TOLERANCE, ftol=BOUNDED_SOLVE_TOLERANCE,
                             gtol=BOUNDED_SOLVE_TOLERANCE, max_nfev=BOUNDED_SOLVE_EVALUATIONS)
    if solution.status <= 0:
        raise RuntimeError(f"signed bending's convexity-bounded solve failed: {solution.message}")
    gamma = unpack(solution.x)
    diagonal = np.array([n != "b01" for n in SIGNED_BENDING_PARAMETERS])
    # On the floor to round-off (u² + p: a sum that rounds above it): exactly on it.
    gamma[diagonal & (gamma <= floor * (1.0 + FLOOR_ROUNDOFF))] = floor
    return dict(zip(SIGNED_BENDING_PARAMETERS, (float(g) for g in gamma)))


def _residual_moments(used: list[SampleResult], relative: np.ndarray) -> dict[str, float]:
    """``m0 m1 m2`` (N): the central difference ``(Ū(+κ) − Ū(−κ))/(2κ)`` of the weft, warp and
    bias bends at their smallest sampled curvature, where a quadratic part of either sign's
    stiffness is ``κ/2`` times smaller than at the range: the moment the repeat carries at rest.
    0 where a family lacks a sample of either sign at its smallest magnitude. (A bias bend's κ2 is
    ±κ with κ0 = κ1 = |κ|/2, so its difference is ``m2``.) Reported, not fitted."""
    moments = {}
    for name, family in (("m0", "weft_bend"), ("m1", "warp_bend"), ("m2", "bias_bend")):
        pairs = {s.parameter: e for s, e in zip(used, relative) if s.family == family}
        magnitudes = sorted({abs(p) for p in pairs if -p in pairs and p != 0.0})
        moments[name] = 0.0
        if magnitudes:
            k = magnitudes[0]
            moments[name] = (pairs[k] - pairs[-k]) / (2.0 * k)
    return moments


def _is_undeformed(sample: SampleResult) -> bool:
    return bool(np.all(sample.I == np.eye(2)) and np.all(sample.II == 0.0))


def _residual_stress_columns(samples: list[SampleResult]) -> np.ndarray:
    """``(n, 6)``: ``dŪ/d(n0 n1 n2 m0 m1 m2)``, the Voigt strains ε and curvatures κ."""
    return np.hstack([membrane_strain(np.stack([s.I for s in samples])),
                      bending_strain(np.stack([s.II for s in samples]))])


# -- helpers --------------------------------------------------------------------------------------


def _fit_group(
    group: str,
    families: tuple[str, ...],
    names: list[str],
    D: np.ndarray,
    target: np.ndarray,
    weights: np.ndarray,
    coupling: tuple[str, str, str],
    coupling_limit: float | None,
) -> tuple[dict[str, float], dict[str, float], list[str], float]:
    """Bounded weighted fit of one group.

    Returns ``(values, standard errors, names at a bound, ratio)``: the names of diagonals at the
    floor, and the coupling's name if it ended on ``|c| = coupling_limit √(d0 d1)`` (``coupling``
    = (d0, c, d1); ``None`` leaves it unbounded); ``ratio`` is ``c/√(d0 d1)`` of the fit without
    the coupling bound (NaN when the coupling is not fitted).
    """
    sw = np.sqrt(weights)
    A = sw[:, None] * D
    b = sw * target
    # Unit-norm columns: entries are ~1e-6 J/m² per Pa against parameters of 1e5–1e7 Pa, and the
    # shear/twist columns are smaller than the stretch/bend ones; scaled, the solve, the floor and the
    # rank test do not depend on units.
    scale = np.linalg.norm(A, axis=0)
    if np.any(scale == 0.0):
        zero = [n for n, c in zip(names, scale) if c == 0.0]
        raise ValueError(
            f"{', '.join(zero)} undetermined: no used {group} sample ({', '.join(families)}) strains "
            f"{'it' if len(zero) == 1 else 'them'} with non-zero weight"
        )
    As = A / scale
    if np.linalg.matrix_rank(As) < len(names):
        # The right singular vector of the smallest singular value names the confounded parameters.
        null = np.linalg.svd(As)[2][-1]
        mixed = [n for n, v in zip(names, null) if abs(v) > 0.1]
        raise ValueError(f"the {group} samples do not determine {', '.join(mixed)} separately (rank-deficient design)")

    unbounded = np.linalg.lstsq(As, b, rcond=None)[0] / scale
    diagonal = np.array([n in _DIAGONAL for n in names])
    largest = float(np.max(unbounded[diagonal]))
    if not largest > 0.0:
        raise ValueError(
            f"no {group} diagonal stiffness comes out positive in the unbounded fit "
            f"({', '.join(f'{n} = {v:.6g} Pa' for n, v in zip(names, unbounded))}): the energies of "
            f"{', '.join(families)} are not positive"
        )
    floor = DIAGONAL_FLOOR_REL * largest
    lower = np.where(diagonal, floor * scale, -np.inf)
    result = lsq_linear(As, b, bounds=(lower, np.full(len(names), np.inf)), method="bvls")
    if not result.success:
        raise RuntimeError(f"{group} least-squares solve failed: {result.message}")
    x = result.x
    at_bound = diagonal & (result.active_mask == -1)

    ratio = math.nan
    coupled = coupling[1] in names
    if coupled:
        i0, ic, i1 = (names.index(n) for n in coupling)
        ratio = _coupling_ratio(x / scale, i0, ic, i1)
        if coupling_limit is not None and not at_bound[[i0, i1]].any() and abs(ratio) > coupling_limit:
            x = _coupling_bounded_solve(As, b, lower, (i0, ic, i1), scale, coupling_limit, x)
            at_bound = diagonal & (x <= lower)
            at_bound[ic] = True
    values = x / scale
    values[at_bound & diagonal] = floor  # exact floor, not floor·scale/scale

    n, p = len(b), len(names)
    if n > p:
        r = A @ values - b
        variance = float(r @ r) / (n - p)
        # (AᵀA)⁺ = A⁺ A⁺ᵀ, computed on the scaled columns and unscaled: cov_ij = cov'_ij / (c_i c_j).
        # At an active bound this is the covariance of the unconstrained linearisation.
        pinv = np.linalg.pinv(As)
        errors = np.sqrt(variance * np.sum(pinv**2, axis=1)) / scale
    else:
        errors = np.full(p, np.nan)
    return (
        dict(zip(names, values.tolist())),
        dict(zip(names, errors.tolist())),
        [n for n, a in zip(names, at_bound) if a],
        ratio,
    )


def _coupling_ratio(values: np.ndarray, i0: int, ic: int, i1: int) -> float:
    """``c/√(d0 d1)`` (±inf if a diagonal is not positive)."""
    product = values[i0] * values[i1]
    return float(values[ic] / math.sqrt(product)) if product > 0.0 else math.copysign(math.inf, values[ic])


def _coupling_bounded_solve(
    As: np.ndarray, b: np.ndarray, lower: np.ndarray, block: tuple[int, int, int], scale: np.ndarray,
    limit: float, start: np.ndarray,
) -> np.ndarray:
    """``min ‖As x − b‖`` subject to ``x ≥ lower`` and ``|c| ≤ limit √(d0 d1)`` for the block's
    unscaled values ``d0 = x[i0]/scale[i0]`` etc.; returns the scaled solution ``x``.

    Solved in ``(u, v, ρ, rest)`` with ``x[i0] = u²``, ``x[i1] = v²``, ``x[ic] = ρ u v k`` (``k =
    scale[ic]/√(scale[i0] scale[i1])``), ``ρ ∈ [−limit, limit]``: the bounded set of x is a convex
    cone and the objective convex, so the local optimum this finds from the projected ``start`` is
    the global one.
    """
    i0, ic, i1 = block
    k = scale[ic] / math.sqrt(scale[i0] * scale[i1])
    rest = [j for j in range(len(start)) if j not in block]

    def unpack(theta):
        u, v, rho = theta[:3]
        x = np.empty(len(start))
        x[i0], x[i1], x[ic] = u * u, v * v, rho * u * v * k
        x[rest] = theta[3:]
        return x

    def residual(theta):
        return As @ unpack(theta) - b

    def jacobian(theta):
        u, v, rho = theta[:3]
        J = np.empty((len(b), len(theta)))
        J[:, 0] = 2.0 * u * As[:, i0] + rho * v * k * As[:, ic]
        J[:, 1] = 2.0 * v * As[:, i1] + rho * u * k * As[:, ic]
        J[:, 2] = u * v * k * As[:, ic]
        J[:, 3:] = As[:, rest]
        return J

    u0, v0 = math.sqrt(max(start[i0], lower[i0])), math.sqrt(max(start[i1], lower[i1]))
    theta0 = np.concatenate([[u0, v0, math.copysign(limit, start[ic])], np.maximum(start[rest], lower[rest])])
    low = np.concatenate([[math.sqrt(lower[i0]), math.sqrt(lower[i1]), -limit], lower[rest]])
    high = np.concatenate([[np.inf, np.inf, limit], np.full(len(rest), np.inf)])
    solution = least_squares(residual, theta0, jac=jacobian, bounds=(low, high), method="trf",
                             xtol=BOUNDED_SOLVE_TOLERANCE, ftol=BOUNDED_SOLVE_TOLERANCE,
                             gtol=BOUNDED_SOLVE_TOLERANCE, max_nfev=BOUNDED_SOLVE_EVALUATIONS)
    if solution.status <= 0:
        raise RuntimeError(f"coupling-bounded least-squares solve failed: {solution.message}")
    x = unpack(solution.x)
    x[ic] = math.copysign(limit, x[ic]) * math.sqrt(x[i0] * x[i1]) * k if abs(solution.x[2]) >= limit else x[ic]
    return x


def _family_statistics(used: list[SampleResult], fitted: np.ndarray, target: np.ndarray,
                       counted: np.ndarray | None = None) -> dict[str, dict]:
    """Per family of ``used`` (only the samples ``counted``, a boolean mask, if given) the R², the
    relative RMS error and the sample count of ``fitted`` against ``target`` (see :func:`fit_shell`)."""
    stats = {}
    for family in FAMILIES:
        mask = np.array([s.family == family for s in used], dtype=bool)
        if counted is not None:
            mask &= counted
        if not np.any(mask):
            continue
        u, res = target[mask], fitted[mask] - target[mask]
        ss_res = float(res @ res)
        ss_tot = float(np.sum((u - u.mean()) ** 2))
        r2 = 1.0 - ss_res / ss_tot if ss_tot > 0.0 else (1.0 if ss_res == 0.0 else -math.inf)
        rms_u = math.sqrt(float(u @ u) / len(u))
        rms_res = math.sqrt(ss_res / len(u))
        relative_rms = rms_res / rms_u if rms_u > 0.0 else (0.0 if rms_res == 0.0 else math.inf)
        stats[family] = {"r2": r2, "relative_rms": relative_rms, "samples": int(mask.sum())}
    return stats


def _thickness(thickness: object) -> float:
    h = real_number(thickness, "thickness")
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"thickness must be finite and > 0 (m), got {h!r}")
    return h


def _sample_list(samples: Iterable[SampleResult]) -> list[SampleResult]:
    samples = list(samples)
    if not samples:
        raise ValueError("samples is empty")
    for k, s in enumerate(samples):
        if not isinstance(s, SampleResult):
            raise ValueError(f"samples[{k}] must be a SampleResult, got {type(s).__name__}")
    return samples


def _params(params: Sequence[float]) -> np.ndarray:
    gamma = np.asarray(params, dtype=np.float64)
    if gamma.shape != (len(PARAMETER_NAMES),):
        raise ValueError(
            f"params must have shape ({len(PARAMETER_NAMES)},) ordered as {PARAMETER_NAMES}, got shape {gamma.shape}"
        )
    return gamma


def _weights(weights: np.ndarray, n: int) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n,) or not np.all(np.isfinite(w)) or np.any(w < 0.0):
        raise ValueError(f"weights must be {n} finite non-negative numbers, got shape {w.shape}")
    return w


def _json_families(families: dict[str, dict]) -> dict[str, dict]:
    return {name: {"r2": finite_or_none(f["r2"]), "relative_rms": finite_or_none(f["relative_rms"]),
                   "samples": f["samples"]}
            for name, f in families.items()}

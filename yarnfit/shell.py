"""Orthotropic StVK shell material: the model the yarn-level energies are fitted to.

Conventions (``docs/design.md`` §3), SI units throughout:

* Material axes: weft = t = first axis (x), warp = p = second axis (y). The rest surface is flat and
  its metric is the identity.
* Membrane strain: Green strain ``E = ½(I − Id)`` with ``I`` the first fundamental form (2×2, SPD,
  dimensionless), in Voigt form ``ε = (E_tt, E_pp, 2 E_tp)``. Energy per reference area
  ``W_s = (h/2) εᵀ S ε`` (J/m²) with ``S = [[s00, s01, 0], [s01, s11, 0], [0, 0, s22]]`` (Pa) and
  ``h`` the shell thickness (m).
* Bending strain: ``κ = (II_tt, II_pp, 2 II_tp)`` with ``II`` the second fundamental form (2×2
  symmetric, 1/m). Energy per area ``W_b = (h³/2) κᵀ B κ`` (J/m²) with
  ``B = [[b00, b01, 0], [b01, b11, 0], [0, 0, b22]]`` (Pa). The paper's model has ``b01 = 0``.
* Strain stiffening (optional, :class:`NonlinearMembrane`, ``docs/design.md`` §3): the membrane
  energy gains ``h Σ_d φ_d(y_d)`` with ``φ_d(y) = k2 y³/3 + k3 y⁴/4`` per direction ``d``, one pair
  ``(k2, k3)`` (Pa) for ``y_d ≥ 0`` and one for ``y_d < 0``, on the stiffening strains
  ``y = (ε0 + c01 ε1, ε1 + c10 ε0, ε2)``, and ``h Σ_d ½ q_d min(ε_d, 0)²``: each Voigt direction's
  tangent is ``S_dd + q_d`` where its strain is negative (weft or warp compression, negative
  shear). ``S`` is the tangent at zero strain on the tension side (every ``ε_d ≥ 0``).
* Moduli (paper Eq. shell_stiffness_moduli), ``D = 1 − ν_tp ν_pt``: ``s00 = E_t/D``, ``s11 = E_p/D``,
  ``s01 = ν_pt E_t/D = ν_tp E_p/D``, ``s22 = μ``.

Matrix arguments. ``I`` and ``II`` are given as full 2×2 matrices, one ``(2, 2)`` or a stack
``(n, 2, 2)``. The energy reads them through their symmetric part, so the off-diagonal strains are
``2 E_tp = (I_01 + I_10)/2`` and ``2 II_tp = II_01 + II_10``. :meth:`ShellMaterial.energy_gradient`
returns the derivative with respect to each entry on its own, which is therefore symmetric:
``dW/dI = (h/2) [[σ_0, σ_2], [σ_2, σ_1]]`` with ``σ = S ε + Dᵀ φ'(y)`` and ``dW/dII = h³ [[m_0, m_2], [m_2, m_1]]``
with ``m = B κ``. A symmetric variation that changes both ``I_01`` and ``I_10`` by ``d`` changes
``W`` by ``2 d (dW/dI)_01``, i.e. the usual Frobenius pairing ``⟨dW/dI, dI⟩``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq

from .checks import check_keys, finite_number, non_negative_number

__all__ = [
    "BENDING_PARAMETERS",
    "GF_CM2_PER_CM",
    "MEMBRANE_PARAMETERS",
    "NONLINEAR_COMPRESSION_KEYS",
    "NONLINEAR_COUPLING_KEYS",
    "NONLINEAR_KEYS",
    "NonlinearMembrane",
    "PARAMETER_NAMES",
    "ShellMaterial",
    "as_first_fundamental_form",
    "as_second_fundamental_form",
    "bending_strain",
    "membrane_strain",
]

MEMBRANE_PARAMETERS = ("s00", "s01", "s11", "s22")
BENDING_PARAMETERS = ("b00", "b01", "b11", "b22")
# The order of the fit's parameter vector γ and of ShellMaterial.parameters.
PARAMETER_NAMES = MEMBRANE_PARAMETERS + BENDING_PARAMETERS

# The strain-stiffening terms' names (plugin config keys and material-file keys): the stiffness they
# act along (s00: weft strain ε0, s11: warp strain ε1, s22: shear strain ε2), the strain's sign
# (p: ε ≥ 0, n: ε < 0) and the power of the strain in the stress term (2: k2 ε², 3: k3 ε³), Pa.
NONLINEAR_DIRECTIONS = ("s00", "s11", "s22")
NONLINEAR_SIDES = ("p", "n")
NONLINEAR_KEYS = tuple(f"{d}{side}{power}" for d in NONLINEAR_DIRECTIONS for side in NONLINEAR_SIDES for power in (2, 3))
# The stiffening strains' coupling (NonlinearMembrane.coupling): y0 = ε0 + c01 ε1, y1 = ε1 + c10 ε0.
NONLINEAR_COUPLING_KEYS = ("c01", "c10")
# The compression-side terms (NonlinearMembrane.compression, Pa): q_d added to the tangent S_dd where
# the Voigt strain ε_d < 0 (weft, warp compression; negative shear). Plugin config and file keys.
NONLINEAR_COMPRESSION_KEYS = ("s00c", "s11c", "s22c")
NONLINEAR_MODEL = "green-polynomial"

# 1 gf·cm²/cm = 1 gf·cm = 9.80665e-3 N × 1e-2 m (N·m): KES-F and cantilever bending rigidity units.
GF_CM2_PER_CM = 9.80665e-5

# Largest accepted asymmetry |A_01 − A_10| of a fundamental form, relative to its largest entry.
# Forms built as FᵀF are symmetric to round-off (~1e-16); 1e-8 is far above that yet far below any
# shear strain a sample resolves (≥ 1e-4), so reading the symmetric part changes nothing that matters.
SYMMETRY_RTOL = 1e-8
# Largest accepted relative mismatch |ν_pt E_t − ν_tp E_p| / max(|ν_pt E_t|, |ν_tp E_p|) in
# from_moduli. Moduli from moduli() or printed with repr agree to round-off (~1e-15); a mismatch above
# one part per million means the two Poisson ratios describe different materials, not a rounding.
RECIPROCITY_RTOL = 1e-6


def as_first_fundamental_form(I: object) -> np.ndarray:
    """``I`` as a float64 array ``(2, 2)`` or ``(n, 2, 2)``, checked finite, symmetric and SPD.

    Raises:
        ValueError: wrong shape, non-finite entries, asymmetry above :data:`SYMMETRY_RTOL` or a
            symmetric part that is not positive definite (the message shows the offending matrix).
    """
    forms = _as_forms(I, "first fundamental form")
    flat = forms.reshape(-1, 2, 2)
    bad = ~_finite_each(flat) | ~_symmetric_each(flat)
    sym = 0.5 * (flat + np.swapaxes(flat, -1, -2))
    det = sym[:, 0, 0] * sym[:, 1, 1] - sym[:, 0, 1] * sym[:, 1, 0]
    with np.errstate(invalid="ignore"):
        bad |= ~((sym[:, 0, 0] > 0.0) & (det > 0.0))
    if np.any(bad):
        raise ValueError(
            f"first fundamental form must be symmetric positive definite, got {_describe(flat, bad, forms.ndim)}"
        )
    return forms


def as_second_fundamental_form(II: object) -> np.ndarray:
    """``II`` (1/m) as a float64 array ``(2, 2)`` or ``(n, 2, 2)``, checked finite and symmetric.

    Raises:
        ValueError: wrong shape, non-finite entries or asymmetry above :data:`SYMMETRY_RTOL`.
    """
    forms = _as_forms(II, "second fundamental form")
    flat = forms.reshape(-1, 2, 2)
    bad = ~_finite_each(flat) | ~_symmetric_each(flat)
    if np.any(bad):
        raise ValueError(
            f"second fundamental form must be finite and symmetric, got {_describe(flat, bad, forms.ndim)}"
        )
    return forms


def membrane_strain(I: object) -> np.ndarray:
    """Voigt membrane strain ``ε = (E_tt, E_pp, 2 E_tp)`` of ``E = ½(I − Id)``, dimensionless.

    Args:
        I: first fundamental form, ``(2, 2)`` or ``(n, 2, 2)``, SPD.

    Returns:
        ``(3,)`` or ``(n, 3)``; ``2 E_tp = (I_01 + I_10)/2``.
    """
    forms = as_first_fundamental_form(I)
    return _membrane_voigt(forms)


def bending_strain(II: object) -> np.ndarray:
    """Voigt bending strain ``κ = (II_tt, II_pp, 2 II_tp)`` (1/m).

    Args:
        II: second fundamental form (1/m), ``(2, 2)`` or ``(n, 2, 2)``, symmetric.

    Returns:
        ``(3,)`` or ``(n, 3)``; ``2 II_tp = II_01 + II_10``.
    """
    forms = as_second_fundamental_form(II)
    return _bending_voigt(forms)


@dataclass(frozen=True)
class NonlinearMembrane:
    """Strain-stiffening (or -softening) terms of an orthotropic membrane (``docs/design.md`` §3).

    Each yarn direction stiffens with its own *stiffening strain*: the stress the linear part
    carries along it, over its axial stiffness,

        y = (ε0 + c01 ε1, ε1 + c10 ε0, ε2),   c01 = s01/s00, c10 = s01/s11 (the material's ``coupling``),

    and the energy per reference area and thickness gains ``Σ_d φ_d(y_d)``, ``φ_d(y) = k2 y³/3 +
    k3 y⁴/4`` (Pa) with one pair ``(k2, k3)`` for ``y ≥ 0`` and one for ``y < 0``. The stress (the
    derivative in ε) gains ``Dᵀ φ'(y)`` with ``D = ∂y/∂ε``, ``φ' = k2 y² + k3 y³``. φ is C² at zero,
    so the material's ``S`` stays the exact small-strain tangent; frame-invariant, a function of
    the Green strain.

    **Compression side** (``compression`` = ``(q0, q1, q2)``, Pa): the energy also gains
    ``Σ_d ½ q_d min(ε_d, 0)²`` on the Voigt strains themselves, so where ``ε_d < 0`` (weft or warp
    compression, negative shear) that direction's tangent is ``S_dd + q_d``; ``S`` is then the
    tension side's tangent at zero strain. C¹ at zero, not C². What it is for: a fabric pulled at
    free width compresses across the pull, and how much it contracts, so how soft the pull is,
    depends on the *transverse* direction's compression stiffness, which differs from its
    tension stiffness and between the two directions (a twill's warp gives under compression, its
    weft does not: free-width over fixed-width energy 0.11 pulled along weft, 0.87 along warp; any
    quadratic ``S`` gives both ``1 − s01²/(s00 s11)``). Acting on ε, not y: a knit's ``S`` is near
    rank one, where both stiffening strains follow the one stiff combination (the yarn length) and
    vanish at free width. Why the stress and not the strain along a direction: a knit's membrane is
    near rank one; pulled at free width its courses lengthen while its wales shorten and the yarn
    hardly stretches (``y0 = (1 − s01²/s00 s11) ε0``, 2 % of ε0 for cotton jersey), while at fixed
    width (``y0 = ε0``) its loops jam and it stiffens eightfold. Stiffening on ε0 alone put the
    jersey's free-width pull at 3.4 kN/m at 10 % against 10 N/m in its yarn swatch.

    What it cannot represent: a coupling s01 that changes with strain (so a Poisson ratio that
    does, beyond the tension/compression switch), stiffening that depends on more than each
    direction's stiffening strain and sign, hysteresis and friction (it is elastic), and buckling
    (a flat membrane under compression).

    Attributes:
        coefficients: the twelve ``k`` (Pa) in :data:`NONLINEAR_KEYS` order, a tuple of floats;
            every ``k3`` (``…3``) is >= 0.
        coupling: ``(c01, c10)``, dimensionless (``(0, 0)``: each direction's own strain).
        compression: ``(q0, q1, q2)`` (Pa), the compression-side tangent changes, any sign.
    """

    coefficients: tuple[float, ...]
    coupling: tuple[float, float] = (0.0, 0.0)
    compression: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        values = tuple(self.coefficients) if not isinstance(self.coefficients, Mapping) else None
        if values is None or len(values) != len(NONLINEAR_KEYS):
            raise ValueError(f"NonlinearMembrane needs {len(NONLINEAR_KEYS)} coefficients ({', '.join(NONLINEAR_KEYS)}), "
                             f"got {self.coefficients!r}")
        values = tuple(finite_number(v, k) for k, v in zip(NONLINEAR_KEYS, values))
        negative = [f"{k} = {v!r}" for k, v in zip(NONLINEAR_KEYS, values) if k.endswith("3") and v < 0.0]
        if negative:
            raise ValueError(f"the cubic stress terms must be >= 0 (a negative one makes the energy concave at large "
                             f"strain): {', '.join(negative)}")
        coupling = tuple(self.coupling)
        if len(coupling) != 2:
            raise ValueError(f"NonlinearMembrane.coupling must be (c01, c10), got {self.coupling!r}")
        coupling = tuple(finite_number(v, k) for k, v in zip(NONLINEAR_COUPLING_KEYS, coupling))
        compression = tuple(self.compression)
        if len(compression) != 3:
            raise ValueError(f"NonlinearMembrane.compression must be (q0, q1, q2), got {self.compression!r}")
        compression = tuple(finite_number(v, k) for k, v in zip(NONLINEAR_COMPRESSION_KEYS, compression))
        object.__setattr__(self, "coefficients", values)
        object.__setattr__(self, "coupling", coupling)
        object.__setattr__(self, "compression", compression)

    @classmethod
    def from_keys(cls, terms: Mapping[str, float]) -> NonlinearMembrane:
        """From ``{key: value}`` (:data:`NONLINEAR_KEYS` in Pa, ``c01`` and ``c10``,
        :data:`NONLINEAR_COMPRESSION_KEYS` in Pa); a key left out is 0, an unknown one is an error."""
        allowed = NONLINEAR_KEYS + NONLINEAR_COUPLING_KEYS + NONLINEAR_COMPRESSION_KEYS
        unknown = sorted(set(terms) - set(allowed))
        if unknown:
            raise ValueError(f"unknown nonlinear membrane keys: {', '.join(unknown)} (allowed: {', '.join(allowed)})")
        return cls(tuple(terms.get(key, 0.0) for key in NONLINEAR_KEYS),
                   tuple(terms.get(key, 0.0) for key in NONLINEAR_COUPLING_KEYS),
                   tuple(terms.get(key, 0.0) for key in NONLINEAR_COMPRESSION_KEYS))

    @classmethod
    def coupling_of(cls, s00: float, s01: float, s11: float) -> tuple[float, float]:
        """``(c01, c10) = (s01/s00, s01/s11)``: the stiffening strains of a membrane ``S``."""
        return (s01 / s00, s01 / s11)

    @property
    def keys(self) -> dict[str, float]:
        """Every value by name: the twelve terms (Pa, :data:`NONLINEAR_KEYS`), ``c01``, ``c10``, then
        the compression side's ``s00c s11c s22c`` (Pa) (the plugin's config keys)."""
        return {**dict(zip(NONLINEAR_KEYS, self.coefficients)), **dict(zip(NONLINEAR_COUPLING_KEYS, self.coupling)),
                **dict(zip(NONLINEAR_COMPRESSION_KEYS, self.compression))}

    @property
    def table(self) -> np.ndarray:
        """The coefficients as ``(3, 2, 2)``: direction (y0, y1, y2), side (y ≥ 0, y < 0), (k2, k3)."""
        return np.array(self.coefficients).reshape(3, 2, 2)

    @property
    def map(self) -> np.ndarray:
        """``D = ∂y/∂ε`` ``(3, 3)``."""
        c01, c10 = self.coupling
        return np.array([[1.0, c01, 0.0], [c10, 1.0, 0.0], [0.0, 0.0, 1.0]])

    @property
    def is_zero(self) -> bool:
        """No term at all: the membrane is its quadratic part."""
        return not any(self.coefficients) and not any(self.compression)

    def stiffening_strain(self, eps: np.ndarray) -> np.ndarray:
        """``y`` for Voigt strains ``eps (…, 3)``, same shape."""
        return np.asarray(eps, dtype=np.float64) @ self.map.T

    def _sided(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(k2, k3)`` arrays shaped like ``y (…, 3)``: each stiffening strain's own side's pair."""
        table = self.table
        negative = y < 0.0
        k2 = np.where(negative, table[:, 1, 0], table[:, 0, 0])
        k3 = np.where(negative, table[:, 1, 1], table[:, 0, 1])
        return k2, k3

    def energy(self, eps: np.ndarray) -> np.ndarray:
        """``Σ_d φ_d(y_d) + Σ_d ½ q_d min(ε_d, 0)²`` (Pa = J/m³) for Voigt strains ``eps (…, 3)``;
        shape ``(…)``."""
        eps = np.asarray(eps, dtype=np.float64)
        y = self.stiffening_strain(eps)
        k2, k3 = self._sided(y)
        compressed = np.minimum(eps, 0.0)
        return np.sum(k2 * y**3 / 3.0 + k3 * y**4 / 4.0 + 0.5 * np.array(self.compression) * compressed**2, axis=-1)

    def stress(self, eps: np.ndarray) -> np.ndarray:
        """``Dᵀ φ'(y) + q min(ε, 0)`` (Pa), the derivative of :meth:`energy` in ε, shaped like
        ``eps (…, 3)``."""
        eps = np.asarray(eps, dtype=np.float64)
        y = self.stiffening_strain(eps)
        k2, k3 = self._sided(y)
        return (k2 * y**2 + k3 * y**3) @ self.map + np.array(self.compression) * np.minimum(eps, 0.0)

    def hessian(self, eps: np.ndarray) -> np.ndarray:
        """``Dᵀ diag(φ''(y)) D + diag(q [ε < 0])`` ``(…, 3, 3)`` (Pa), ``φ'' = 2 k2 y + 3 k3 y²``."""
        eps = np.asarray(eps, dtype=np.float64)
        y = self.stiffening_strain(eps)
        k2, k3 = self._sided(y)
        D = self.map
        compressed = np.where(eps < 0.0, np.array(self.compression), 0.0)
        return (np.einsum("ki,...k,kj->...ij", D, 2.0 * k2 * y + 3.0 * k3 * y**2, D)
                + compressed[..., :, None] * np.eye(3))

    def softening(self) -> np.ndarray:
        """``(3,)`` least ``φ_d''`` over all strains (Pa, <= 0): ``−k2²/(3 k3)`` on a side whose
        ``k2`` softens (``k2 < 0`` for y ≥ 0, ``k2 > 0`` for y < 0), ``−inf`` if its ``k3`` is 0."""
        least = np.zeros(3)
        for d, ((k2p, k3p), (k2n, k3n)) in enumerate(self.table):
            for soft, k3 in ((max(0.0, -k2p), k3p), (max(0.0, k2n), k3n)):
                if soft > 0.0:
                    least[d] = min(least[d], -soft * soft / (3.0 * k3) if k3 > 0.0 else -math.inf)
        return least

    def least_tangent(self, s00: float, s01: float, s11: float, s22: float) -> np.ndarray:
        """``S + Dᵀ diag(softening()) D + diag(min(q, 0))`` ``(3, 3)``: below every tangent the
        membrane has."""
        m = self.softening()
        if np.any(np.isinf(m)):
            return np.full((3, 3), -np.inf)
        return self._tangent_with(m, s00, s01, s11, s22) + np.diag(np.minimum(self.compression, 0.0))

    def stiffest(self, bound: float) -> np.ndarray:
        """``(3,)`` largest ``φ_d''`` (Pa, >= 0) over stiffening strains ``|y_d| <= bound`` on both
        sides: ``φ''`` is convex in y (every ``k3 >= 0``), so its largest value on each side is at
        zero (0) or at the bound (``2 k2 b + 3 k3 b²``, ``−2 k2 b + 3 k3 b²`` below zero)."""
        bound = non_negative_number(bound, "bound")
        largest = np.zeros(3)
        for d, ((k2p, k3p), (k2n, k3n)) in enumerate(self.table):
            largest[d] = max(0.0, 2.0 * k2p * bound + 3.0 * k3p * bound**2,
                             -2.0 * k2n * bound + 3.0 * k3n * bound**2)
        return largest

    def largest_tangent(self, s00: float, s01: float, s11: float, s22: float, bound: float) -> np.ndarray:
        """``S + Dᵀ diag(stiffest(bound)) D + diag(max(q, 0))`` ``(3, 3)`` (Pa): above every tangent
        the membrane has while each stiffening strain stays within ``±bound``."""
        return self._tangent_with(self.stiffest(bound), s00, s01, s11, s22) + np.diag(np.maximum(self.compression, 0.0))

    def _tangent_with(self, second: np.ndarray, s00: float, s01: float, s11: float, s22: float) -> np.ndarray:
        """``S + Dᵀ diag(second) D`` ``(3, 3)`` (Pa) for ``φ_d'' = second (3,)``."""
        D = self.map
        S = np.array([[s00, s01, 0.0], [s01, s11, 0.0], [0.0, 0.0, s22]])
        return S + D.T @ np.diag(second) @ D

    def convexity_problems(self, s00: float, s01: float, s11: float, s22: float) -> list[str]:
        """Why :meth:`least_tangent` is not positive definite with this ``S`` (empty if it is):
        then the membrane energy is convex in the Green strain at every strain."""
        H = self.least_tangent(s00, s01, s11, s22)
        problems = _block_problems(float(H[0, 0]), float(H[0, 1]) if np.isfinite(H[0, 1]) else 0.0, float(H[1, 1]),
                                   float(H[2, 2]), ("(s00 + min stiffening)", "s01", "(s11 + min stiffening)",
                                                    "(s22 + min stiffening)"))
        return [f"the stiffening terms make the membrane non-convex: {p}" for p in problems]

    def to_dict(self) -> dict:
        """JSON form: ``{"model": "green-polynomial", "stress_terms_pa": {key: Pa},
        "stiffening_strain": {"c01": …, "c10": …}, "compression_pa": {"s00c": …, "s11c": …,
        "s22c": …}}``."""
        return {"model": NONLINEAR_MODEL, "stress_terms_pa": dict(zip(NONLINEAR_KEYS, self.coefficients)),
                "stiffening_strain": dict(zip(NONLINEAR_COUPLING_KEYS, self.coupling)),
                "compression_pa": dict(zip(NONLINEAR_COMPRESSION_KEYS, self.compression))}

    @classmethod
    def from_dict(cls, data: Mapping, where: str = "shell material") -> NonlinearMembrane:
        """Inverse of :meth:`to_dict`; ValueError ``<where>: …`` naming the key at fault. A file
        without ``compression_pa`` (written before it existed) has none."""
        _check_keys(data, ("model", "stress_terms_pa", "stiffening_strain"), where, "nonlinear.", ("compression_pa",))
        if data["model"] != NONLINEAR_MODEL:
            raise ValueError(f"{where}: nonlinear.model must be {NONLINEAR_MODEL!r}, got {data['model']!r}")
        _check_keys(data["stress_terms_pa"], NONLINEAR_KEYS, where, "nonlinear.stress_terms_pa.")
        _check_keys(data["stiffening_strain"], NONLINEAR_COUPLING_KEYS, where, "nonlinear.stiffening_strain.")
        terms = {k: _json_number(data["stress_terms_pa"][k], where, f"nonlinear.stress_terms_pa.{k}")
                 for k in NONLINEAR_KEYS}
        terms.update({k: _json_number(data["stiffening_strain"][k], where, f"nonlinear.stiffening_strain.{k}")
                      for k in NONLINEAR_COUPLING_KEYS})
        if "compression_pa" in data:
            _check_keys(data["compression_pa"], NONLINEAR_COMPRESSION_KEYS, where, "nonlinear.compression_pa.")
            terms.update({k: _json_number(data["compression_pa"][k], where, f"nonlinear.compression_pa.{k}")
                          for k in NONLINEAR_COMPRESSION_KEYS})
        try:
            return cls.from_keys(terms)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None


# Largest transverse or shear stress left by a uniaxial pull's solve, relative to the stress its
# strain makes in the stiffest direction: Newton reaches ~1e-13 in a few steps; 1e-9 flags one
# that did not converge.
UNIAXIAL_STRESS_RTOL = 1e-9
# Newton steps of a uniaxial pull's solve at most (a convex 2-variable problem takes 3–8), and the
# difference step of its Jacobian as a fraction of the pulled strain.
UNIAXIAL_NEWTON_STEPS = 50
UNIAXIAL_FD_STEP = 1e-6
# The uniaxial pull's first guess keeps the free width's Green strain this fraction of the way above
# −½ (zero width): a guess there is admissible, and the Newton steps move from it.
UNIAXIAL_WIDTH_MARGIN = 0.1


class UniaxialPull(NamedTuple):
    """A strip pulled along one direction with every other stress free
    (:meth:`ShellMaterial.uniaxial_pull`)."""

    force_n_per_m: float  # pulling force per reference width (N/m)
    width_ratio: float  # deformed over reference width
    first_form: np.ndarray  # I (2, 2) in the weft/warp frame


@dataclass(frozen=True)
class ShellMaterial:
    """Orthotropic StVK shell: thickness and the membrane and bending stiffness matrices.

    Positive definiteness is not required here: a least-squares fit may produce an indefinite
    candidate, which the fitter reports (see :meth:`check_positive_definite`).

    Attributes:
        thickness: shell thickness h (m), > 0.
        s00, s01, s11, s22: membrane stiffnesses (Pa), entries of ``S``.
        b00, b01, b11, b22: bending stiffnesses (Pa), entries of ``B``.
        nonlinear: the membrane's strain-stiffening terms, or ``None`` (StVK); ``S`` is the
            small-strain tangent either way (in tension, where the terms carry a compression side).
    """

    thickness: float
    s00: float
    s01: float
    s11: float
    s22: float
    b00: float
    b01: float
    b11: float
    b22: float
    nonlinear: NonlinearMembrane | None = None

    def __post_init__(self) -> None:
        for name in ("thickness",) + PARAMETER_NAMES:
            object.__setattr__(self, name, finite_number(getattr(self, name), name))
        if self.thickness <= 0.0:
            raise ValueError(f"thickness must be > 0 (m), got {self.thickness!r}")
        if self.nonlinear is not None and not isinstance(self.nonlinear, NonlinearMembrane):
            raise ValueError(f"nonlinear must be a NonlinearMembrane or None, got {type(self.nonlinear).__name__}")

    @property
    def linear(self) -> ShellMaterial:
        """This material without its strain-stiffening terms (the StVK of its small-strain tangent)."""
        return ShellMaterial(self.thickness, **self.parameters)

    # -- matrices and parameter views ------------------------------------------------------------

    @property
    def S(self) -> np.ndarray:
        """Membrane stiffness matrix ``(3, 3)`` (Pa)."""
        return np.array([[self.s00, self.s01, 0.0], [self.s01, self.s11, 0.0], [0.0, 0.0, self.s22]])

    @property
    def B(self) -> np.ndarray:
        """Bending stiffness matrix ``(3, 3)`` (Pa)."""
        return np.array([[self.b00, self.b01, 0.0], [self.b01, self.b11, 0.0], [0.0, 0.0, self.b22]])

    @property
    def parameters(self) -> dict[str, float]:
        """The eight stiffnesses (Pa) by name, in :data:`PARAMETER_NAMES` order."""
        return {name: getattr(self, name) for name in PARAMETER_NAMES}

    # -- definiteness ------------------------------------------------------------------------------

    @property
    def membrane_positive_definite(self) -> bool:
        """``S`` is positive definite: ``s00 > 0``, ``s00 s11 − s01² > 0`` and ``s22 > 0``."""
        return not _block_problems(self.s00, self.s01, self.s11, self.s22, MEMBRANE_PARAMETERS)

    @property
    def bending_positive_definite(self) -> bool:
        """``B`` is positive definite: ``b00 > 0``, ``b00 b11 − b01² > 0`` and ``b22 > 0``."""
        return not _block_problems(self.b00, self.b01, self.b11, self.b22, BENDING_PARAMETERS)

    def check_positive_definite(self) -> None:
        """Raise ValueError naming the block (membrane/bending) and the entries that fail; with
        stiffening terms, also if they make the membrane energy non-convex at some strain."""
        problems = []
        membrane = _block_problems(self.s00, self.s01, self.s11, self.s22, MEMBRANE_PARAMETERS)
        bending = _block_problems(self.b00, self.b01, self.b11, self.b22, BENDING_PARAMETERS)
        if membrane:
            problems.append(f"membrane block S not positive definite: {'; '.join(membrane)}")
        elif self.nonlinear is not None:
            problems += self.nonlinear.convexity_problems(self.s00, self.s01, self.s11, self.s22)
        if bending:
            problems.append(f"bending block B not positive definite: {'; '.join(bending)}")
        if problems:
            raise ValueError(". ".join(problems))

    # -- moduli and engineering constants --------------------------------------------------------

    @classmethod
    def from_moduli(
        cls,
        thickness: float,
        E_t: float,
        E_p: float,
        nu_tp: float,
        nu_pt: float,
        mu: float,
        b00: float,
        b11: float,
        b22: float,
        b01: float = 0.0,
    ) -> ShellMaterial:
        """A material from in-plane moduli (Pa), Poisson ratios and bending stiffnesses (Pa).

        ``nu_tp`` is the warp contraction under weft load, ``nu_pt`` the weft contraction under warp
        load; symmetry of ``S`` requires ``nu_pt E_t = nu_tp E_p`` (to :data:`RECIPROCITY_RTOL`).

        Raises:
            ValueError: non-positive ``E_t``, ``E_p`` or ``mu``, a reciprocity mismatch, or
                ``D = 1 − nu_tp nu_pt ≤ 0``.
        """
        values = {"E_t": E_t, "E_p": E_p, "nu_tp": nu_tp, "nu_pt": nu_pt, "mu": mu}
        values = {name: finite_number(value, name) for name, value in values.items()}
        for name in ("E_t", "E_p", "mu"):
            if values[name] <= 0.0:
                raise ValueError(f"{name} must be > 0 (Pa), got {values[name]!r}")
        E_t, E_p, nu_tp, nu_pt, mu = (values[k] for k in ("E_t", "E_p", "nu_tp", "nu_pt", "mu"))
        lhs, rhs = nu_pt * E_t, nu_tp * E_p
        scale = max(abs(lhs), abs(rhs))
        if abs(lhs - rhs) > RECIPROCITY_RTOL * scale:
            raise ValueError(
                f"moduli violate reciprocity nu_pt*E_t = nu_tp*E_p: nu_pt*E_t = {lhs!r}, nu_tp*E_p = {rhs!r} "
                f"(relative mismatch {abs(lhs - rhs) / scale:.3g} > {RECIPROCITY_RTOL})"
            )
        D = 1.0 - nu_tp * nu_pt
        if D <= 0.0:
            raise ValueError(f"1 - nu_tp*nu_pt must be > 0, got {D!r} (nu_tp={nu_tp!r}, nu_pt={nu_pt!r})")
        return cls(
            thickness=thickness,
            s00=E_t / D,
            s01=nu_pt * E_t / D,
            s11=E_p / D,
            s22=mu,
            b00=b00,
            b01=b01,
            b11=b11,
            b22=b22,
        )

    def moduli(self) -> dict[str, float]:
        """In-plane moduli: ``E_t``, ``E_p``, ``mu`` (Pa) and ``nu_tp``, ``nu_pt`` (dimensionless).

        Inverse of :meth:`from_moduli`: ``nu_tp = s01/s11``, ``nu_pt = s01/s00``,
        ``D = 1 − s01²/(s00 s11)``, ``E_t = s00 D``, ``E_p = s11 D``, ``mu = s22``.

        Raises:
            ValueError: the membrane block is not positive definite (the moduli would be meaningless).
        """
        self._require_positive_definite("moduli", membrane=True, bending=False)
        D = 1.0 - self.s01**2 / (self.s00 * self.s11)
        return {
            "E_t": self.s00 * D,
            "E_p": self.s11 * D,
            "nu_tp": self.s01 / self.s11,
            "nu_pt": self.s01 / self.s00,
            "mu": self.s22,
        }

    def engineering(self) -> dict[str, float]:
        """The engineering constants every material report carries (units in the key).

        Stretch and shear stiffnesses are per unit width (N/m); the uniaxial ones leave the
        transverse direction free, which a small pull compresses when ``s01 > 0``: with compression
        terms (:attr:`NonlinearMembrane.compression`) its tangent there is ``s11 + q1`` (``s00 + q0``
        for a warp pull), :meth:`pull_tangent`. Shear is the positive side's, ``h s22`` (a negative
        shear meets ``h (s22 + q2)``). Bending rigidities (N·m) are ``B_dir`` with ``½ B_dir k²`` the
        energy per area of a cylindrical bend of curvature ``k`` whose curvature direction is along
        weft, along warp, or at 45° (bias).

        Raises:
            ValueError: ``S`` or ``B`` is not positive definite.
        """
        self._require_positive_definite("engineering constants", membrane=True, bending=True)
        h = self.thickness
        across_weft = float(self.pull_tangent(0.0)[1, 1])  # s11, or s11 + q1 where the pull compresses it
        across_warp = float(self.pull_tangent(0.5 * math.pi)[0, 0])
        return {
            "weft_stretch_n_per_m": h * (self.s00 - self.s01**2 / across_weft),
            "warp_stretch_n_per_m": h * (self.s11 - self.s01**2 / across_warp),
            "poisson_weft": self.s01 / across_weft,
            "poisson_warp": self.s01 / across_warp,
            "shear_n_per_m": h * self.s22,
            "bending_weft_nm": h**3 * self.b00,
            "bending_warp_nm": h**3 * self.b11,
            "bending_bias_nm": h**3 * (self.b00 + self.b11 + 2.0 * self.b01 + 4.0 * self.b22) / 4.0,
        }

    # -- energy ------------------------------------------------------------------------------------

    def energy_density(self, I: object, II: object) -> float | np.ndarray:
        """Energy per reference area ``W = W_s + W_b`` (J/m²), with the stiffening terms if any.

        Args:
            I: first fundamental form, ``(2, 2)`` or ``(n, 2, 2)``.
            II: second fundamental form (1/m), ``(2, 2)`` or ``(n, 2, 2)``; leading shapes broadcast.

        Returns:
            a float for two ``(2, 2)`` inputs, else an array ``(n,)``.
        """
        eps, kap, single = self._strains(I, II)
        h = self.thickness
        W = 0.5 * h * np.einsum("...i,ij,...j->...", eps, self.S, eps)
        if self.nonlinear is not None:
            W = W + h * self.nonlinear.energy(eps)
        W = W + 0.5 * h**3 * np.einsum("...i,ij,...j->...", kap, self.B, kap)
        return float(W) if single else W

    def pull_tangent(self, angle: float) -> np.ndarray:
        """``(3, 3)`` (Pa): the small-strain tangent a pull at ``angle`` (rad) from weft meets, every
        other stress free: ``S`` plus each compression term ``q_d`` whose strain that pull makes
        negative. The law is piecewise linear at small strain (one piece per sign pattern of ε);
        the pull's strain is the one pattern consistent with itself, which a convex membrane has
        (its stress is a monotone function of its strain). Without compression terms, ``S``."""
        S = self.S
        q = np.zeros(3) if self.nonlinear is None else np.array(self.nonlinear.compression)
        if not np.any(q):
            return S
        c, s = math.cos(angle), math.sin(angle)
        load = np.array([c * c, s * s, c * s])
        # Strains within round-off of zero may sit on either side (a pull along weft has no shear).
        tolerance = 1e-12
        for compressed in itertools.product((False, True), repeat=3):
            tangent = S + np.diag(np.where(compressed, q, 0.0))
            if not np.all(np.linalg.eigvalsh(tangent) > 0.0):
                continue
            eps = np.linalg.solve(tangent, load)
            scale = tolerance * float(np.abs(eps).max())
            if all((e <= scale) if k else (e >= -scale) for e, k in zip(eps, compressed)):
                return tangent
        raise ValueError(f"no small-strain state of a pull at {angle!r} rad is consistent with its compression terms "
                         f"(a non-convex membrane?)")

    def uniaxial_stiffness(self, angle: float) -> tuple[float, float]:
        """Small-strain uniaxial stiffness (N/m) and Poisson ratio for a pull at ``angle`` (rad)
        from weft, the transverse direction free: the rotated compliance of ``h`` times the pull's
        tangent (:meth:`pull_tangent`: ``S``, with the compression terms the pull engages). At 0
        and π/2 these are ``weft_stretch_n_per_m``, ``poisson_weft`` and the warp ones."""
        c, s = math.cos(angle), math.sin(angle)
        compliance = np.linalg.inv(self.thickness * self.pull_tangent(angle))
        load = np.array([c * c, s * s, c * s])
        across = np.array([s * s, c * c, -c * s])
        along = float(load @ compliance @ load)
        return 1.0 / along, -float(across @ compliance @ load) / along

    def uniaxial_tension(self, axis: int, stretch: float) -> tuple[np.ndarray, float]:
        """Uniaxial tension along weft (``axis`` 0) or warp (1) with the other direction free:
        ``(I (2, 2), W)``. The free Green strain minimises W: for StVK ``E_other = −(s01/s_other) E``
        with ``E = (stretch² − 1)/2`` and ``W = (h/2) (s_axis − s01²/s_other) E²`` (J/m²), the
        free-width stiffness of the engineering constants; with stiffening terms it is the root of
        the transverse stress ``(S ε + Dᵀ φ'(y))_other = 0`` (increasing in E_other for a convex
        membrane). Needs a positive-definite, convex membrane."""
        if axis not in (0, 1):
            raise ValueError(f"axis must be 0 (weft) or 1 (warp), got {axis!r}")
        stretch = finite_number(stretch, "stretch")
        if stretch <= 0.0:
            raise ValueError(f"stretch must be positive, got {stretch!r}")
        self._require_positive_definite("uniaxial tension states", membrane=True, bending=False)
        along, other = (self.s00, self.s11) if axis == 0 else (self.s11, self.s00)
        strain = 0.5 * (stretch**2 - 1.0)
        free = -self.s01 / other * strain
        if self.nonlinear is None or self.nonlinear.is_zero:
            diagonal = [0.0, 0.0]
            diagonal[axis], diagonal[1 - axis] = 1.0 + 2.0 * strain, 1.0 + 2.0 * free
            return np.diag(diagonal), 0.5 * self.thickness * (along - self.s01**2 / other) * strain**2
        problems = self.nonlinear.convexity_problems(self.s00, self.s01, self.s11, self.s22)
        if problems:
            raise ValueError(f"uniaxial tension states need a convex membrane: {'; '.join(problems)}")

        def form(free_strain: float) -> np.ndarray:
            diagonal = [0.0, 0.0]
            diagonal[axis], diagonal[1 - axis] = 1.0 + 2.0 * strain, 1.0 + 2.0 * free_strain
            return np.diag(diagonal)

        def transverse_stress(free_strain: float) -> float:
            eps = np.zeros(3)
            eps[axis], eps[1 - axis] = strain, free_strain
            return float((self.S @ eps)[1 - axis] + self.nonlinear.stress(eps)[1 - axis])

        # Bracket the root: the stress rises with the free strain (convex membrane), and the free
        # Green strain cannot fall below −½ (a vanishing transverse stretch).
        low, high = -0.5 + 1e-12, max(abs(free), abs(strain), 1e-12)
        while transverse_stress(high) < 0.0:
            high *= 2.0
        if transverse_stress(low) > 0.0:
            raise ValueError(f"uniaxial tension at stretch {stretch!r}: no free width balances the transverse stress")
        free = brentq(transverse_stress, low, high, xtol=1e-15, rtol=4.0 * np.finfo(float).eps)
        I = form(free)
        return I, float(self.energy_density(I, np.zeros((2, 2))))

    def uniaxial_pull(self, angle: float, stretch: float) -> UniaxialPull:
        """A long strip pulled to ``stretch`` at ``angle`` (rad) from weft, every other stress
        free: in the frame of the pull the Green strain is ``[[e, γ], [γ, f]]`` with
        ``e = (stretch² − 1)/2`` and ``f``, ``γ`` such that the transverse and shear stresses
        vanish (``Qᵀ (dW/dI) Q`` zero but for its first entry). The force per reference width is
        ``dW/dλ = 2 λ (Qᵀ (dW/dI) Q)₀₀`` (N/m) and the width ratio ``√det I / λ`` (the distance
        between the strip's long edges, which stay lines along the pull). At 0 and π/2 this is
        :meth:`uniaxial_tension` (no shear there for an orthotropic membrane); at small strain the
        force is ``uniaxial_stiffness(angle)[0] · (λ − 1)``. Needs a positive-definite membrane."""
        angle = finite_number(angle, "angle")
        stretch = finite_number(stretch, "stretch")
        if stretch <= 0.0:
            raise ValueError(f"stretch must be positive, got {stretch!r}")
        self._require_positive_definite("uniaxial pulls", membrane=True, bending=False)
        c, s = math.cos(angle), math.sin(angle)
        q = np.array([[c, -s], [s, c]])  # columns: the pull direction and its normal
        strain = 0.5 * (stretch**2 - 1.0)
        flat = np.zeros((2, 2))

        def first_form(free: np.ndarray) -> np.ndarray:
            green = np.array([[strain, free[1]], [free[1], free[0]]])
            return np.eye(2) + 2.0 * q @ green @ q.T

        def rotated_gradient(free: np.ndarray) -> np.ndarray:
            return q.T @ self.energy_gradient(first_form(free), flat)[0] @ q

        # Newton on (f, γ), whose residuals are W's derivatives (∂W/∂f = 2 g₁₁, ∂W/∂γ = 4 g₀₁), with
        # a central-difference Jacobian and steps halved until W or the residual falls (W is convex
        # in them for a convex membrane; near the root its changes are below W's round-off), from the
        # small-strain Poisson contraction.
        def energy(free: np.ndarray) -> float:
            return float(self.energy_density(first_form(free), flat))

        def gradient(free: np.ndarray) -> np.ndarray:
            g = rotated_gradient(free)
            return np.array([2.0 * g[1, 1], 4.0 * g[0, 1]])

        def admissible(free: np.ndarray) -> bool:  # the pulled sheet keeps a positive width
            form = first_form(free)
            return bool(form[1, 1] > 0.0 and np.linalg.det(form) > 0.0)

        # The small-strain Poisson contraction, kept inside the admissible widths: a knit's ν ≈ 1.5
        # at 40 % would ask for a negative squared width.
        free = np.array([max(-self.uniaxial_stiffness(angle)[1] * strain, -0.5 * (1.0 - UNIAXIAL_WIDTH_MARGIN)), 0.0])
        # Residuals are judged against the stress the pulled strain makes in the stiffest
        # direction: a bias pull of a satin (s22 ~ 1e-5 s00) has a pulling stress below the
        # round-off of its weft and warp stresses.
        scale = max(self.thickness * float(np.abs(self.S).max()) * abs(strain), 1e-300)
        step = UNIAXIAL_FD_STEP * max(abs(strain), 1e-6)
        for _ in range(UNIAXIAL_NEWTON_STEPS):
            g = gradient(free)
            if np.abs(g).max() <= UNIAXIAL_STRESS_RTOL * scale:
                break
            if not all(admissible(free + sign * step * e) for e in np.eye(2) for sign in (1.0, -1.0)):
                break  # at the edge of the admissible widths: no free width balances the pull
            jacobian = np.column_stack([(gradient(free + step * e) - gradient(free - step * e)) / (2.0 * step)
                                        for e in np.eye(2)])
            direction = -np.linalg.solve(0.5 * (jacobian + jacobian.T), g)
            if not float(g @ direction) < 0.0:
                direction = -g  # an indefinite difference Jacobian: steepest descent instead
            alpha, start, imbalance = 1.0, energy(free), float(np.abs(g).max())
            while alpha > 1e-12 and not (admissible(free + alpha * direction)
                                         and (energy(free + alpha * direction) < start
                                              or float(np.abs(gradient(free + alpha * direction)).max()) < imbalance)):
                alpha *= 0.5
            free = free + alpha * direction
        if np.abs(gradient(free)).max() > UNIAXIAL_STRESS_RTOL * scale:
            raise ValueError(f"uniaxial pull at {math.degrees(angle):g}° to stretch {stretch!r}: no free width and "
                             f"shear balance the transverse stresses (the width collapses, or the membrane is not "
                             f"convex)")
        I = first_form(free)
        return UniaxialPull(
            force_n_per_m=2.0 * stretch * float(rotated_gradient(free)[0, 0]),
            width_ratio=math.sqrt(float(np.linalg.det(I))) / stretch,
            first_form=I,
        )

    def energy_gradient(self, I: object, II: object) -> tuple[np.ndarray, np.ndarray]:
        """``(dW/dI, dW/dII)``: derivative of :meth:`energy_density` with respect to each matrix entry.

        See the module docstring for the convention: both are symmetric,
        ``dW/dI = (h/2) [[σ_0, σ_2], [σ_2, σ_1]]`` (J/m²) with ``σ = S ε + Dᵀ φ'(y)`` and
        ``dW/dII = h³ [[m_0, m_2], [m_2, m_1]]`` (J/m) with ``m = B κ``.

        Returns:
            two arrays ``(2, 2)`` for ``(2, 2)`` inputs, else ``(n, 2, 2)``.
        """
        eps, kap, _ = self._strains(I, II)
        shape = np.broadcast_shapes(eps.shape, kap.shape)
        sigma = eps @ self.S  # S symmetric: row-vector product = S ε
        if self.nonlinear is not None:
            sigma = sigma + self.nonlinear.stress(eps)
        sigma = np.broadcast_to(sigma, shape)
        moment = np.broadcast_to(kap @ self.B, shape)
        h = self.thickness
        return 0.5 * h * _voigt_to_matrix(sigma), h**3 * _voigt_to_matrix(moment)

    def _strains(self, I: object, II: object) -> tuple[np.ndarray, np.ndarray, bool]:
        first = as_first_fundamental_form(I)
        second = as_second_fundamental_form(II)
        try:
            np.broadcast_shapes(first.shape, second.shape)
        except ValueError:
            raise ValueError(
                f"I and II must have matching leading shapes, got {first.shape} and {second.shape}"
            ) from None
        return _membrane_voigt(first), _bending_voigt(second), first.ndim == 2 and second.ndim == 2

    def _require_positive_definite(self, what: str, *, membrane: bool, bending: bool) -> None:
        """ValueError if a requested block is indefinite: moduli and rigidities would be meaningless."""
        problems = []
        if membrane:
            problems += _block_problems(self.s00, self.s01, self.s11, self.s22, MEMBRANE_PARAMETERS)
        if bending:
            problems += _block_problems(self.b00, self.b01, self.b11, self.b22, BENDING_PARAMETERS)
        if problems:
            raise ValueError(f"{what} need a positive definite material: {'; '.join(problems)}")

    # -- serialisation -----------------------------------------------------------------------------

    def to_dict(self) -> dict:
        """JSON form: ``{"thickness_m": h, "membrane_pa": {s00, s01, s11, s22}, "bending_pa": {b00, ...}}``,
        plus ``"nonlinear"`` (:meth:`NonlinearMembrane.to_dict`) when the material has stiffening terms."""
        data = {
            "thickness_m": self.thickness,
            "membrane_pa": {name: getattr(self, name) for name in MEMBRANE_PARAMETERS},
            "bending_pa": {name: getattr(self, name) for name in BENDING_PARAMETERS},
        }
        if self.nonlinear is not None:
            data["nonlinear"] = self.nonlinear.to_dict()
        return data

    @classmethod
    def from_dict(cls, data: Mapping, where: str = "shell material") -> ShellMaterial:
        """Inverse of :meth:`to_dict`. Unknown keys are rejected (a misspelt key shows up twice).

        Args:
            data: the mapping written by :meth:`to_dict`.
            where: what to call the source in error messages (a file name).

        Raises:
            ValueError: ``<where>: ...`` naming the missing, unknown or non-numeric key.
        """
        _check_keys(data, ("thickness_m", "membrane_pa", "bending_pa"), where, "", ("nonlinear",))
        fields = {"thickness": _json_number(data["thickness_m"], where, "thickness_m")}
        if "nonlinear" in data:
            fields["nonlinear"] = NonlinearMembrane.from_dict(data["nonlinear"], where)
        for block, names in (("membrane_pa", MEMBRANE_PARAMETERS), ("bending_pa", BENDING_PARAMETERS)):
            _check_keys(data[block], names, where, f"{block}.")
            for name in names:
                fields[name] = _json_number(data[block][name], where, f"{block}.{name}")
        try:
            return cls(**fields)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None


# -- helpers --------------------------------------------------------------------------------------


def _block_problems(d0: float, off: float, d1: float, diag: float, names: tuple[str, ...]) -> list[str]:
    """Why ``[[d0, off], [off, d1]] ⊕ [diag]`` is not positive definite (empty if it is)."""
    n0, n_off, n1, n_diag = names
    problems = []
    if not d0 > 0.0:
        problems.append(f"{n0} = {d0!r} <= 0")
    if not d1 > 0.0:
        problems.append(f"{n1} = {d1!r} <= 0")
    if d0 > 0.0 and d1 > 0.0 and not off * off < d0 * d1:
        problems.append(f"{n_off}² = {off * off!r} >= {n0}·{n1} = {d0 * d1!r} ({n_off} = {off!r})")
    if not diag > 0.0:
        problems.append(f"{n_diag} = {diag!r} <= 0")
    return problems


def _as_forms(a: object, what: str) -> np.ndarray:
    try:
        forms = np.array(a, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a real array of shape (2, 2) or (n, 2, 2), got {a!r}") from None
    if forms.ndim not in (2, 3) or forms.shape[-2:] != (2, 2):
        raise ValueError(f"{what} must have shape (2, 2) or (n, 2, 2), got shape {forms.shape}")
    return forms


def _finite_each(flat: np.ndarray) -> np.ndarray:
    return np.all(np.isfinite(flat), axis=(1, 2))


def _symmetric_each(flat: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        scale = np.max(np.abs(flat), axis=(1, 2))
        return np.abs(flat[:, 0, 1] - flat[:, 1, 0]) <= SYMMETRY_RTOL * scale


def _describe(flat: np.ndarray, bad: np.ndarray, ndim: int) -> str:
    """The first offending matrix as a nested list, with its index for a stack."""
    k = int(np.flatnonzero(bad)[0])
    text = repr(flat[k].tolist())
    return text if ndim == 2 else f"{text} at index {k} (of {len(flat)})"


def _membrane_voigt(I: np.ndarray) -> np.ndarray:
    return np.stack([0.5 * (I[..., 0, 0] - 1.0), 0.5 * (I[..., 1, 1] - 1.0), 0.5 * (I[..., 0, 1] + I[..., 1, 0])], -1)


def _bending_voigt(II: np.ndarray) -> np.ndarray:
    return np.stack([II[..., 0, 0], II[..., 1, 1], II[..., 0, 1] + II[..., 1, 0]], -1)


def _voigt_to_matrix(v: np.ndarray) -> np.ndarray:
    """``(…, 3)`` → ``(…, 2, 2)`` as ``[[v0, v2], [v2, v1]]``."""
    out = np.empty(v.shape[:-1] + (2, 2))
    out[..., 0, 0] = v[..., 0]
    out[..., 1, 1] = v[..., 1]
    out[..., 0, 1] = v[..., 2]
    out[..., 1, 0] = v[..., 2]
    return out


def _check_keys(data: object, required: tuple[str, ...], where: str, prefix: str,
                optional: tuple[str, ...] = ()) -> None:
    """ValueError naming missing and unknown keys of a JSON object (reported together)."""
    if not isinstance(data, Mapping):
        name = prefix.rstrip(".") or "material"
        raise ValueError(f"{where}: {name} must be an object with keys {', '.join(required)}, got {data!r}")
    check_keys(data, required, where, allowed=required + optional, prefix=prefix)


def _json_number(value: object, where: str, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where}: {key} must be a number, got {value!r}")
    return float(value)

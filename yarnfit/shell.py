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
* Strain stiffening (optional, :class:`RidgeMembrane`, ``docs/design.md`` §3): the membrane energy
  per reference area is then ``h ψ(ε)`` with ``ψ = ½ εᵀ Q ε + Σ_j ½ c_j max(n_j·ε − t_j, 0)²``, a
  convex sum of one-sided quadratic ridges, **instead of** ``(h/2) εᵀ S ε``. ``S`` stays the linear
  model fitted to the same samples: what a reader that knows only StVK, ``--linear`` and the
  engineering constants of the linear model use.
* Signed bending (optional, :class:`SignedBending`, ``docs/design.md`` §3): ``b00`` and ``b11``
  take one value for a positive curvature (the surface curving towards its normal, the repeat's
  +z: ``II > 0``) and another for a negative one, **instead of** ``B``; ``B`` stays the symmetric
  model fitted to the same samples (what ``--linear`` and the engineering constants use). A
  jersey bends several times more easily one way than the other.
* Moduli (paper Eq. shell_stiffness_moduli), ``D = 1 − ν_tp ν_pt``: ``s00 = E_t/D``, ``s11 = E_p/D``,
  ``s01 = ν_pt E_t/D = ν_tp E_p/D``, ``s22 = μ``.

Matrix arguments. ``I`` and ``II`` are given as full 2×2 matrices, one ``(2, 2)`` or a stack
``(n, 2, 2)``. The energy reads them through their symmetric part, so the off-diagonal strains are
``2 E_tp = (I_01 + I_10)/2`` and ``2 II_tp = II_01 + II_10``. :meth:`ShellMaterial.energy_gradient`
returns the derivative with respect to each entry on its own, which is therefore symmetric:
``dW/dI = (h/2) [[σ_0, σ_2], [σ_2, σ_1]]`` with ``σ = S ε`` (``∂ψ/∂ε`` with a ridge membrane) and
``dW/dII = h³ [[m_0, m_2], [m_2, m_1]]`` with ``m = B κ``. A symmetric variation that changes both
``I_01`` and ``I_10`` by ``d`` changes ``W`` by ``2 d (dW/dI)_01``, i.e. the usual Frobenius pairing
``⟨dW/dI, dI⟩``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
from numba import njit
from scipy.optimize import brentq

from .checks import check_keys, finite_number, non_negative_number

__all__ = [
    "BENDING_PARAMETERS",
    "GF_CM2_PER_CM",
    "MEMBRANE_PARAMETERS",
    "PARAMETER_NAMES",
    "RIDGE_MODEL",
    "RidgeMembrane",
    "SIGNED_BENDING_PARAMETERS",
    "ShellMaterial",
    "SignedBending",
    "as_first_fundamental_form",
    "as_second_fundamental_form",
    "bending_strain",
    "membrane_strain",
]

MEMBRANE_PARAMETERS = ("s00", "s01", "s11", "s22")
BENDING_PARAMETERS = ("b00", "b01", "b11", "b22")
# The order of the fit's parameter vector γ and of ShellMaterial.parameters.
PARAMETER_NAMES = MEMBRANE_PARAMETERS + BENDING_PARAMETERS

# The strain-stiffening membrane (RidgeMembrane): its model name in the material file, and the names
# of its base's entries (the plugin's s00 … s22 keys carry the base when a ridge membrane is given).
RIDGE_MODEL = "green-ridge"
RIDGE_BASE_KEYS = ("q00", "q01", "q11", "q22")
# Largest |n| − 1 accepted for a ridge direction: written as unit vectors with repr (~1e-16); a
# direction off by more than 1e-9 was not normalised by its writer.
RIDGE_UNIT_RTOL = 1e-9
# Round-off admitted in a direction's tangent (the running sum of its ridges' stiffnesses, which
# must stay >= 0): a fitted tangent on its bound of 0 comes back from differences of ~1e-16 relative.
RIDGE_CONVEXITY_RTOL = 1e-12
# Round-off admitted in the base's semi-definiteness q01² <= q00·q11: a fitted base of rank one
# (a knit's, whose compression carries a single combination) sits on the bound to ~1e-16.
RIDGE_BASE_RTOL = 1e-12

# The signed bending's entries (SignedBending), in its material-file block and field order.
SIGNED_BENDING_PARAMETERS = ("b00_pos", "b00_neg", "b01", "b11_pos", "b11_neg", "b22")

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
class RidgeMembrane:
    """A convex, strain-stiffening orthotropic membrane: a quadratic base and one-sided quadratic
    ridges in the Green strain (``docs/design.md`` §3).

    Energy per reference area and thickness (Pa = J/m³) at Voigt Green strain ``ε = (E00, E11, 2 E01)``:

        ψ(ε) = ½ εᵀ Q ε + Σ_j ½ c_j max(n_j·ε − t_j, 0)²,

    ``Q = [[q00, q01, 0], [q01, q11, 0], [0, 0, q22]]`` positive semi-definite (Pa), and per ridge
    ``j`` a unit direction ``n_j`` in strain space, a knot ``t_j >= 0`` (dimensionless) and a
    stiffness ``c_j`` (Pa) of either sign: along each direction the tangent, the sum of the
    stiffnesses of the ridges passed in knot order, must stay ``>= 0`` (a tangent may fall: a
    yarn's energy in the Green strain softens). Each direction's part is then a convex function of
    a linear map of ε, so ψ is convex at every strain and C¹ (its tangent jumps by ``c_j n_j n_jᵀ``
    where ``n_j·ε`` crosses ``t_j``). Frame-invariant: a function of the Green strain in the
    material frame.

    What it is for: a fabric stiffens as its yarns straighten and its loops or crossings jam, by
    different amounts along every combination of weft, warp and shear strain, and a pull at free
    width follows a path on which the transverse direction is compressed. A sum of ridges along a
    fan of strain directions, each switched on at its own knot, follows energies that grow faster
    than any quadratic along one path and stay soft along another (a knit: soft along the
    mechanism its courses and wales trade length on, stiff once the yarn itself is pulled), and
    stiffer in tension than in compression (ridges with ``t_j = 0`` act on one side of zero only).

    The **small-strain tangent** therefore depends on the direction of the strain: below the
    smallest positive knot ψ is ``½ εᵀ T(ε̂) ε`` with ``T = Q + Σ_{t_j = 0, n_j·ε > 0} c_j n_j n_jᵀ``,
    one matrix per sign pattern. ``Q`` is its part common to every direction.

    What it cannot represent: an energy that is not convex in the Green strain (a membrane that
    buckles in its own plane), hysteresis and friction (it is elastic), a coupling between shear
    and the normal strains beyond what its ridges' directions carry (the fit's ridges lie in the
    normal-strain plane, on the shear axis, and on rays between the two at 45°; for a knit those
    with a shear part tied in pairs mirrored in the shear: an orthotropic membrane, whose coupling
    of shear and normal strains is even in the shear, so a jersey's skew is followed only on
    average over the shear's two signs; a woven's keep one tangent per sign, as its twill line
    shears it stiffer one way, fitted to pulls along both biases),
    and stiffening sharper than its knots resolve (the fit spaces them logarithmically over the
    sampled strains).

    Attributes:
        base: ``(q00, q01, q11, q22)`` (Pa), positive semi-definite.
        ridges: ``((n0, n1, n2, t, c), …)``: a unit direction, its knot (``>= 0``) and stiffness
            (Pa; the running sum along each direction ``>= 0``).
    """

    base: tuple[float, float, float, float]
    ridges: tuple[tuple[float, float, float, float, float], ...] = ()

    def __post_init__(self) -> None:
        base = tuple(self.base)
        if len(base) != 4:
            raise ValueError(f"RidgeMembrane.base must be (q00, q01, q11, q22), got {self.base!r}")
        base = tuple(finite_number(v, f"base.{k}") for k, v in zip(RIDGE_BASE_KEYS, base))
        q00, q01, q11, q22 = base
        if q00 < 0.0 or q11 < 0.0 or q22 < 0.0 or q01 * q01 > q00 * q11 * (1.0 + RIDGE_BASE_RTOL):
            raise ValueError(f"RidgeMembrane.base must be positive semi-definite (q00, q11, q22 >= 0 and "
                             f"q01² <= q00·q11), got {base!r}")
        ridges = []
        for j, ridge in enumerate(self.ridges):
            values = tuple(ridge)
            if len(values) != 5:
                raise ValueError(f"ridge {j} must be (n0, n1, n2, knot, stiffness), got {ridge!r}")
            n0, n1, n2, knot, stiffness = (finite_number(v, f"ridge {j} {k}")
                                           for k, v in zip(("n0", "n1", "n2", "knot", "stiffness"), values))
            norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            if abs(norm - 1.0) > RIDGE_UNIT_RTOL:
                raise ValueError(f"ridge {j}: its direction must be a unit vector, got |n| = {norm!r}")
            if knot < 0.0:
                raise ValueError(f"ridge {j}: its knot must be >= 0, got {knot!r}")
            ridges.append((n0, n1, n2, knot, stiffness))
        # Convex: along every direction the tangent, the sum of the stiffnesses of the ridges passed
        # (in knot order, those at one knot together), never falls below zero.
        for direction, along in _tangents_along(ridges).items():
            scale = max(abs(r[4]) for r in ridges if r[:3] == direction)
            for knot, tangent in along:
                if tangent < -RIDGE_CONVEXITY_RTOL * scale:
                    raise ValueError(f"the ridges along {list(direction)} make the energy concave: past knot "
                                     f"{knot!r} their tangent is {tangent!r} Pa < 0")
        object.__setattr__(self, "base", base)
        object.__setattr__(self, "ridges", tuple(ridges))

    @property
    def Q(self) -> np.ndarray:
        """The base ``(3, 3)`` (Pa)."""
        q00, q01, q11, q22 = self.base
        return np.array([[q00, q01, 0.0], [q01, q11, 0.0], [0.0, 0.0, q22]])

    # The ridges as arrays, built once per membrane (energy, stress and Hessian read them at every
    # call, a uniaxial pull's Newton steps hundreds of times) and read-only, since they are shared.

    @cached_property
    def directions(self) -> np.ndarray:
        """``(k, 3)`` unit ridge directions (read-only)."""
        return _read_only(np.array([r[:3] for r in self.ridges], dtype=np.float64).reshape(-1, 3))

    @cached_property
    def knots(self) -> np.ndarray:
        """``(k,)`` ridge knots (read-only)."""
        return _read_only(np.array([r[3] for r in self.ridges], dtype=np.float64))

    @cached_property
    def stiffness(self) -> np.ndarray:
        """``(k,)`` ridge stiffnesses (Pa, read-only)."""
        return _read_only(np.array([r[4] for r in self.ridges], dtype=np.float64))

    def law(self, eps: np.ndarray, order: int = 2) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """``(ψ (…), ∂ψ/∂ε (…, 3), ∂²ψ/∂ε² (…, 3, 3))`` (Pa) at Voigt strains ``eps (…, 3)`` in one
        pass over the ridges (:func:`_ridge_law`); the derivatives past ``order`` (0, 1 or 2) are
        None. At a kink the side ``n·ε > t`` excludes."""
        eps = np.asarray(eps, dtype=np.float64)
        shape = eps.shape[:-1]
        flat = np.ascontiguousarray(eps.reshape(-1, 3))
        count = flat.shape[0]
        energy = np.empty(count)
        stress = np.empty((count if order >= 1 else 0, 3))
        tangent = np.empty((count if order >= 2 else 0, 3, 3))
        _ridge_law(flat, self.Q, self.directions, self.knots, self.stiffness, order, energy, stress, tangent)
        return (energy.reshape(shape), stress.reshape(shape + (3,)) if order >= 1 else None,
                tangent.reshape(shape + (3, 3)) if order >= 2 else None)

    def energy(self, eps: np.ndarray) -> np.ndarray:
        """``ψ = ½ εᵀ Q ε + ½ Σ_j c_j max(n_j·ε − t_j, 0)²`` (Pa = J/m³) at Voigt strains
        ``eps (…, 3)``; shape ``(…)``."""
        return self.law(eps, 0)[0]

    def stress(self, eps: np.ndarray) -> np.ndarray:
        """``∂ψ/∂ε = Q ε + Σ_j c_j max(n_j·ε − t_j, 0) n_j`` (Pa), shaped like ``eps (…, 3)``."""
        return self.law(eps, 1)[1]

    def hessian(self, eps: np.ndarray) -> np.ndarray:
        """``Q + Σ_j c_j [n_j·ε > t_j] n_j n_jᵀ`` ``(…, 3, 3)`` (Pa)."""
        return self.law(eps, 2)[2]

    def largest_tangent(self, bound: float) -> np.ndarray:
        """``Q + Σ_n T_n n nᵀ`` ``(3, 3)`` (Pa), ``T_n`` the largest tangent along direction ``n``
        over the knots a strain with every ``|ε_d| <= bound`` reaches (``t <= |n|₁ bound``; at 0 the
        one-sided ridges at zero): above every tangent the membrane has there, softening ridges
        included."""
        bound = non_negative_number(bound, "bound")
        largest = self.Q.copy()
        for direction, along in _tangents_along(self.ridges).items():
            n = np.array(direction)
            reached = [tangent for knot, tangent in along if knot <= np.abs(n).sum() * bound]
            if reached:
                largest += max(max(reached), 0.0) * np.outer(n, n)
        return largest

    @property
    def plugin_keys(self) -> dict[str, str]:
        """The ``yarnfit.shell`` plugin's membrane keys for this membrane (``plugins/README.md``):
        ``s00 s01 s11 s22`` = the base (Pa) and ``ridges``, five numbers per ridge (``n0 n1 n2 t c``),
        every float written with ``repr`` (round trip)."""
        keys = {name: repr(float(v)) for name, v in zip(MEMBRANE_PARAMETERS, self.base)}
        keys["ridges"] = " ".join(repr(float(v)) for ridge in self.ridges for v in ridge)
        return keys

    def to_dict(self) -> dict:
        """JSON form: ``{"model": "green-ridge", "base_pa": {"s00": …, "s01": …, "s11": …, "s22": …},
        "ridges": [{"direction": [n0, n1, n2], "knot": t, "stiffness_pa": c}, …]}``."""
        return {"model": RIDGE_MODEL, "base_pa": dict(zip(MEMBRANE_PARAMETERS, self.base)),
                "ridges": [{"direction": list(r[:3]), "knot": r[3], "stiffness_pa": r[4]} for r in self.ridges]}

    @classmethod
    def from_dict(cls, data: Mapping, where: str = "shell material") -> RidgeMembrane:
        """Inverse of :meth:`to_dict`; ValueError ``<where>: …`` naming the key at fault. A file
        of an earlier yarnfit's membrane model (``green-polynomial``) is refused with what to do."""
        if isinstance(data, Mapping) and data.get("model") == "green-polynomial":
            raise ValueError(f"{where}: nonlinear.model 'green-polynomial' (an earlier yarnfit's strain-stiffening "
                             f"membrane) is no longer supported: fit the fabric again (yarnfit fit), or export "
                             f"--linear")
        _check_keys(data, ("model", "base_pa", "ridges"), where, "nonlinear.")
        if data["model"] != RIDGE_MODEL:
            raise ValueError(f"{where}: nonlinear.model must be {RIDGE_MODEL!r}, got {data['model']!r}")
        _check_keys(data["base_pa"], MEMBRANE_PARAMETERS, where, "nonlinear.base_pa.")
        base = tuple(_json_number(data["base_pa"][k], where, f"nonlinear.base_pa.{k}") for k in MEMBRANE_PARAMETERS)
        if not isinstance(data["ridges"], list):
            raise ValueError(f"{where}: nonlinear.ridges must be a list, got {data['ridges']!r}")
        ridges = []
        for j, ridge in enumerate(data["ridges"]):
            at = f"nonlinear.ridges[{j}]"
            _check_keys(ridge, ("direction", "knot", "stiffness_pa"), where, f"{at}.")
            direction = ridge["direction"]
            if not isinstance(direction, list) or len(direction) != 3:
                raise ValueError(f"{where}: {at}.direction must be a list of 3 numbers, got {direction!r}")
            ridges.append(tuple(_json_number(v, where, f"{at}.direction") for v in direction)
                          + (_json_number(ridge["knot"], where, f"{at}.knot"),
                             _json_number(ridge["stiffness_pa"], where, f"{at}.stiffness_pa")))
        try:
            return cls(base, tuple(ridges))
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None


@dataclass(frozen=True)
class SignedBending:
    """An orthotropic bending whose weft and warp stiffnesses depend on the curvature's sign
    (``docs/design.md`` §3).

    Energy per reference area, over ``h³`` (Pa/m² = J/m⁵), at ``κ = (II00, II11, 2 II01)``:

        ½ (b00(κ0) κ0² + 2 b01 κ0 κ1 + b11(κ1) κ1² + b22 κ2²),

    ``b00(κ0) = b00_pos`` for ``κ0 >= 0`` (the surface curving towards its normal along weft),
    ``b00_neg`` below; ``b11`` the same along warp. A quadratic on each quadrant of ``(κ0, κ1)``
    whose gradient ``B(κ) κ`` is continuous across the axes (the jump of ``b00`` multiplies
    ``κ0 = 0``), so the energy is C¹, and convex when every quadrant's matrix is positive definite:
    ``b01² < min(b00_pos, b00_neg) · min(b11_pos, b11_neg)`` (along any line the slope is then
    continuous and rises on every piece). Frame-invariant as ``B`` is: a function of the second
    form in the material frame.

    What it is for: a jersey's loops stand out of one face, so bent towards one face its wales or
    courses nest and towards the other they are pulled straight; at zero membrane force cotton
    jersey's weft bend costs 4 times more one way and its warp bend 800 times.

    What it cannot represent: a coupling ``b01`` that depends on the quadrant (a jersey's saddle
    bent one way costs ~3 times its weft and warp bends together, the other way their sum; one
    ``b01`` follows one of them), twist stiffness that depends on the twist's sign, a natural
    curvature (the energy is least flat), and bending that is not quadratic on each side.

    Attributes: the six stiffnesses (Pa), :data:`SIGNED_BENDING_PARAMETERS` order.
    """

    b00_pos: float
    b00_neg: float
    b01: float
    b11_pos: float
    b11_neg: float
    b22: float

    def __post_init__(self) -> None:
        for name in SIGNED_BENDING_PARAMETERS:
            object.__setattr__(self, name, finite_number(getattr(self, name), name))

    @property
    def parameters(self) -> dict[str, float]:
        """The six stiffnesses (Pa) by name."""
        return {name: getattr(self, name) for name in SIGNED_BENDING_PARAMETERS}

    @property
    def positive_definite(self) -> bool:
        """Every quadrant's matrix positive definite (the energy strictly convex)."""
        return not self.problems()

    def problems(self) -> list[str]:
        """Why the energy is not strictly convex (empty when it is)."""
        problems = [f"{name} = {getattr(self, name)!r} <= 0" for name in SIGNED_BENDING_PARAMETERS
                    if name != "b01" and not getattr(self, name) > 0.0]
        if not problems and not self.b01**2 < min(self.b00_pos, self.b00_neg) * min(self.b11_pos, self.b11_neg):
            problems.append(f"b01² = {self.b01**2!r} >= min(b00_pos, b00_neg)·min(b11_pos, b11_neg) = "
                            f"{min(self.b00_pos, self.b00_neg) * min(self.b11_pos, self.b11_neg)!r}")
        return problems

    @property
    def upper(self) -> np.ndarray:
        """``(3, 3)`` (Pa): the matrix with the stiffer side of each direction, above every
        quadrant's (their difference is diagonal and non-negative)."""
        return np.array([[max(self.b00_pos, self.b00_neg), self.b01, 0.0],
                         [self.b01, max(self.b11_pos, self.b11_neg), 0.0], [0.0, 0.0, self.b22]])

    def matrix(self, kap: np.ndarray) -> np.ndarray:
        """The quadrant's matrix at curvatures ``kap (…, 3)`` (1/m): ``(…, 3, 3)`` (Pa)."""
        kap = np.asarray(kap, dtype=np.float64)
        out = np.zeros(kap.shape[:-1] + (3, 3))
        out[..., 0, 0] = np.where(kap[..., 0] >= 0.0, self.b00_pos, self.b00_neg)
        out[..., 1, 1] = np.where(kap[..., 1] >= 0.0, self.b11_pos, self.b11_neg)
        out[..., 0, 1] = out[..., 1, 0] = self.b01
        out[..., 2, 2] = self.b22
        return out

    def energy(self, kap: np.ndarray) -> np.ndarray:
        """``½ κᵀ B(κ) κ`` (Pa/m²) at ``kap (…, 3)`` (1/m); shape ``(…)``."""
        kap = np.asarray(kap, dtype=np.float64)
        return 0.5 * np.einsum("...i,...ij,...j->...", kap, self.matrix(kap), kap)

    def moment(self, kap: np.ndarray) -> np.ndarray:
        """``∂/∂κ`` of :meth:`energy`, ``B(κ) κ`` (Pa/m), shaped like ``kap (…, 3)``."""
        kap = np.asarray(kap, dtype=np.float64)
        return np.einsum("...ij,...j->...i", self.matrix(kap), kap)

    @property
    def plugin_keys(self) -> dict[str, str]:
        """The ``yarnfit.shell`` plugin's bending keys (``plugins/README.md``): ``b00`` and ``b11``
        the positive side's, ``b00_neg`` and ``b11_neg`` the negative side's, ``b01`` and ``b22``;
        every float written with ``repr``."""
        return {"b00": repr(self.b00_pos), "b00_neg": repr(self.b00_neg), "b01": repr(self.b01),
                "b11": repr(self.b11_pos), "b11_neg": repr(self.b11_neg), "b22": repr(self.b22)}

    def to_dict(self) -> dict:
        """JSON form: ``{"b00_pos": …, "b00_neg": …, "b01": …, "b11_pos": …, "b11_neg": …, "b22": …}`` (Pa)."""
        return self.parameters

    @classmethod
    def from_dict(cls, data: Mapping, where: str = "shell material") -> SignedBending:
        """Inverse of :meth:`to_dict`; ValueError ``<where>: …`` naming the key at fault."""
        _check_keys(data, SIGNED_BENDING_PARAMETERS, where, "signed_bending_pa.")
        return cls(**{k: _json_number(data[k], where, f"signed_bending_pa.{k}") for k in SIGNED_BENDING_PARAMETERS})


@njit(cache=True)
def _ridge_law(eps, Q, directions, knots, stiffness, order, energy, stress, tangent):
    """The :class:`RidgeMembrane`'s law at each of ``eps (N, 3)`` (Voigt Green strains): ``ψ`` into
    ``energy (N,)``, and for ``order`` >= 1 ``∂ψ/∂ε`` into ``stress (N, 3)``, for ``order`` >= 2
    ``∂²ψ/∂ε²`` into ``tangent (N, 3, 3)`` (Pa). A ridge acts where ``n·ε − t > 0``."""
    for p in range(eps.shape[0]):
        e0, e1, e2 = eps[p, 0], eps[p, 1], eps[p, 2]
        psi = 0.0
        for i in range(3):
            s = Q[i, 0] * e0 + Q[i, 1] * e1 + Q[i, 2] * e2
            psi += 0.5 * s * eps[p, i]
            if order >= 1:
                stress[p, i] = s
            if order >= 2:
                for j in range(3):
                    tangent[p, i, j] = Q[i, j]
        for k in range(knots.shape[0]):
            n0, n1, n2 = directions[k, 0], directions[k, 1], directions[k, 2]
            excess = n0 * e0 + n1 * e1 + n2 * e2 - knots[k]
            if excess > 0.0:
                c = stiffness[k]
                psi += 0.5 * c * excess * excess
                if order >= 1:
                    stress[p, 0] += c * excess * n0
                    stress[p, 1] += c * excess * n1
                    stress[p, 2] += c * excess * n2
                if order >= 2:
                    for i in range(3):
                        for j in range(3):
                            tangent[p, i, j] += c * directions[k, i] * directions[k, j]
        energy[p] = psi


def _read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _tangents_along(ridges) -> dict[tuple[float, float, float], list[tuple[float, float]]]:
    """Per ridge direction (exactly equal ``n``), ``[(knot, tangent past it), …]`` in knot order:
    the running sum of the stiffnesses of the ridges at or below each knot."""
    along: dict[tuple[float, float, float], dict[float, float]] = {}
    for n0, n1, n2, knot, stiffness in ridges:
        knots = along.setdefault((n0, n1, n2), {})
        knots[knot] = knots.get(knot, 0.0) + stiffness
    out = {}
    for direction, knots in along.items():
        tangent, steps = 0.0, []
        for knot in sorted(knots):
            tangent += knots[knot]
            steps.append((knot, tangent))
        out[direction] = steps
    return out


# The strain of the small pull and shear that give a RidgeMembrane's small-strain constants
# (ShellMaterial.uniaxial_stiffness): below every positive knot the fit places (RIDGE_LEAST_KNOT in
# yarnfit.fit, 2e-3), where ψ is exactly piecewise quadratic and the secant is the tangent, and far
# above the pull solve's round-off (its residual is relative to the pulled strain).
SMALL_STRAIN = 1e-6

# Largest transverse or shear stress left by a uniaxial pull's solve, relative to the stress its
# strain makes in the stiffest direction: Newton reaches ~1e-13 in a few steps; 1e-9 flags one
# that did not converge.
UNIAXIAL_STRESS_RTOL = 1e-9
# Newton steps of a uniaxial pull's solve at most: a convex 2-variable problem takes 3–8, a ridge
# membrane's piecewise quadratic one a step or two per piece it crosses (tens at most).
UNIAXIAL_NEWTON_STEPS = 100
# The regularisation of its Newton steps, relative to the stiffest tangent: far below any stiffness
# a free strain of a real fabric has (>= 1e-6 of the stiffest: a satin's shear), so it changes no
# step there, but it turns a step along a flat direction of a ridge membrane (no stiffness at all
# until a ridge engages) into a long descent step that the halving shortens; 50 halvings reach
# UNIAXIAL_LEAST_STEP from 1 and cover the 1e12 it can overshoot by. It is the floor of a
# Levenberg–Marquardt regularisation: multiplied by UNIAXIAL_REGULARISATION_GROWTH after a step
# the halving had to shorten, divided by it after a full step. A fixed one let the search zigzag
# across a kink: the satin's fitted membrane (its base S zero) pulled along the weft to 1.128 %
# stepped its shear from +0.0037 to 0 and back, each step 2e-6 of a Newton step along the flat
# width, for 100 steps (10,000 reached the root); the growing one takes 17 at most over 1500 pulls
# of the five presets (0.05–12 %, five angles), within 1.1e-5 of the fixed one's force where both
# converge.
UNIAXIAL_REGULARISATION = 1e-12
UNIAXIAL_REGULARISATION_GROWTH = 10.0
UNIAXIAL_LEAST_STEP = 1e-16
# A step is taken when it lowers W, or, where W's change is within this relative round-off of W
# (near the root, W's changes drown in its round-off), when it lowers the residual. Accepting a
# lower residual at any energy let Newton cycle between two pieces of a ridge membrane (a
# polyester jersey's warp pull at 10 %: the step across the kink lowered W, the step back lowered
# the residual).
UNIAXIAL_ENERGY_ROUNDOFF = 1e-12
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
        nonlinear: the strain-stiffening membrane (:class:`RidgeMembrane`), which then *is* the
            membrane (energy ``h ψ(ε)``), or ``None`` (StVK, ``(h/2) εᵀ S ε``). ``S`` is the linear
            model either way: fitted to the same samples, what :attr:`linear` keeps.
        signed_bending: the bending whose weft and warp stiffnesses depend on the curvature's sign
            (:class:`SignedBending`), which then *is* the bending (energy ``h³`` times its own), or
            ``None`` (``(h³/2) κᵀ B κ``). ``B`` is the symmetric model either way.
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
    nonlinear: RidgeMembrane | None = None
    signed_bending: SignedBending | None = None

    def __post_init__(self) -> None:
        for name in ("thickness",) + PARAMETER_NAMES:
            object.__setattr__(self, name, finite_number(getattr(self, name), name))
        if self.thickness <= 0.0:
            raise ValueError(f"thickness must be > 0 (m), got {self.thickness!r}")
        if self.nonlinear is not None and not isinstance(self.nonlinear, RidgeMembrane):
            raise ValueError(f"nonlinear must be a RidgeMembrane or None, got {type(self.nonlinear).__name__}")
        if self.signed_bending is not None and not isinstance(self.signed_bending, SignedBending):
            raise ValueError(f"signed_bending must be a SignedBending or None, got "
                             f"{type(self.signed_bending).__name__}")

    @property
    def linear(self) -> ShellMaterial:
        """This material's linear model: StVK with ``S`` and ``B``, without the strain-stiffening
        membrane and the signed bending."""
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
        """Raise ValueError naming the block (membrane/bending/signed bending) and the entries that
        fail. (A :class:`RidgeMembrane` is convex by construction: its own checks run when it is
        made.)"""
        problems = []
        membrane = _block_problems(self.s00, self.s01, self.s11, self.s22, MEMBRANE_PARAMETERS)
        bending = _block_problems(self.b00, self.b01, self.b11, self.b22, BENDING_PARAMETERS)
        if membrane:
            problems.append(f"membrane block S not positive definite: {'; '.join(membrane)}")
        if bending:
            problems.append(f"bending block B not positive definite: {'; '.join(bending)}")
        if self.signed_bending is not None and not self.signed_bending.positive_definite:
            problems.append(f"signed bending not convex: {'; '.join(self.signed_bending.problems())}")
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

        Stretch and shear stiffnesses are per unit width (N/m) at small strain; the uniaxial ones
        leave the transverse direction free (:meth:`uniaxial_stiffness`). For StVK the closed forms
        of ``S``; with a :class:`RidgeMembrane` its own small-strain response (a pull and a shear to
        :data:`SMALL_STRAIN`), whose tangent depends on the strain's direction: shear is then the
        positive side's. Bending rigidities (N·m) are ``B_dir`` with ``½ B_dir k²`` the energy per
        area of a cylindrical bend of curvature ``k`` whose curvature direction is along weft, along
        warp, or at 45° (bias).

        Raises:
            ValueError: ``S`` or ``B`` is not positive definite.
        """
        self._require_positive_definite("engineering constants", membrane=True, bending=True)
        h = self.thickness
        weft, poisson_weft = self.uniaxial_stiffness(0.0)
        warp, poisson_warp = self.uniaxial_stiffness(0.5 * math.pi)
        if self.nonlinear is None:
            shear = h * self.s22
        else:
            shear = 2.0 * h * float(self.nonlinear.energy(np.array([0.0, 0.0, SMALL_STRAIN]))) / SMALL_STRAIN**2
        return {
            "weft_stretch_n_per_m": weft,
            "warp_stretch_n_per_m": warp,
            "poisson_weft": poisson_weft,
            "poisson_warp": poisson_warp,
            "shear_n_per_m": shear,
            "bending_weft_nm": h**3 * self.b00,
            "bending_warp_nm": h**3 * self.b11,
            "bending_bias_nm": h**3 * (self.b00 + self.b11 + 2.0 * self.b01 + 4.0 * self.b22) / 4.0,
        }

    # -- energy ------------------------------------------------------------------------------------

    def energy_density(self, I: object, II: object) -> float | np.ndarray:
        """Energy per reference area ``W = W_s + W_b`` (J/m²), ``W_s = h`` :meth:`membrane_energy`.

        Args:
            I: first fundamental form, ``(2, 2)`` or ``(n, 2, 2)``.
            II: second fundamental form (1/m), ``(2, 2)`` or ``(n, 2, 2)``; leading shapes broadcast.

        Returns:
            a float for two ``(2, 2)`` inputs, else an array ``(n,)``.
        """
        eps, kap, single = self._strains(I, II)
        h = self.thickness
        W = h * self.membrane_energy(eps) + h**3 * self.bending_energy(kap)
        return float(W) if single else W

    def bending_energy(self, kap: np.ndarray) -> np.ndarray:
        """The bending's energy per reference area over ``h³`` (Pa/m²) at Voigt curvatures
        ``kap (…, 3)`` (1/m): the :class:`SignedBending`'s, or ``½ κᵀ B κ``; shape ``(…)``."""
        kap = np.asarray(kap, dtype=np.float64)
        if self.signed_bending is not None:
            return self.signed_bending.energy(kap)
        return 0.5 * np.einsum("...i,ij,...j->...", kap, self.B, kap)

    def bending_moment(self, kap: np.ndarray) -> np.ndarray:
        """``∂/∂κ`` of :meth:`bending_energy` (Pa/m), shaped like ``kap (…, 3)``."""
        kap = np.asarray(kap, dtype=np.float64)
        if self.signed_bending is not None:
            return self.signed_bending.moment(kap)
        return kap @ self.B  # B symmetric

    def membrane_law(self, eps: np.ndarray, order: int = 2) -> tuple[np.ndarray, np.ndarray | None,
                                                                       np.ndarray | None]:
        """The membrane's energy per reference area and thickness ``ψ(ε)`` (Pa = J/m³), its
        gradient and its tangent at Voigt strains ``eps (…, 3)``, shaped ``(…)``, ``(…, 3)`` and
        ``(…, 3, 3)`` (those past ``order``, 0 to 2, None): the :class:`RidgeMembrane`'s, in one
        pass over its ridges (piecewise constant tangent: at a kink, the side ``n·ε > t``
        excludes), or ``½ εᵀ S ε``, ``S ε`` and ``S``."""
        eps = np.asarray(eps, dtype=np.float64)
        if self.nonlinear is not None:
            return self.nonlinear.law(eps, order)
        stress = eps @ self.S  # S symmetric: row-vector product = S ε
        return (0.5 * np.einsum("...i,...i->...", eps, stress), stress if order >= 1 else None,
                np.broadcast_to(self.S, eps.shape[:-1] + (3, 3)) if order >= 2 else None)

    def membrane_energy(self, eps: np.ndarray) -> np.ndarray:
        """``ψ(ε)`` (Pa = J/m³) of :meth:`membrane_law`, shaped ``(…)``."""
        return self.membrane_law(eps, 0)[0]

    def membrane_stress(self, eps: np.ndarray) -> np.ndarray:
        """``∂ψ/∂ε`` (Pa) of :meth:`membrane_law`, shaped like ``eps (…, 3)``."""
        return self.membrane_law(eps, 1)[1]

    def membrane_tangent(self, eps: np.ndarray) -> np.ndarray:
        """``∂²ψ/∂ε²`` ``(…, 3, 3)`` (Pa) of :meth:`membrane_law`."""
        return self.membrane_law(eps, 2)[2]

    def uniaxial_stiffness(self, angle: float) -> tuple[float, float]:
        """Small-strain uniaxial stiffness (N/m) and Poisson ratio for a pull at ``angle`` (rad)
        from weft, the transverse direction free. StVK: the rotated compliance of ``h S``. With a
        :class:`RidgeMembrane`: a pull to ``1 +`` :data:`SMALL_STRAIN`'s force over ``λ e`` and
        transverse Green strain over ``−e`` (``e`` the pulled Green strain), which are its tangent's
        (ψ is piecewise quadratic below its least positive knot). At 0 and π/2 these are
        ``weft_stretch_n_per_m``, ``poisson_weft`` and the warp ones."""
        if self.nonlinear is not None:
            # In the pull's Green strains (e along, f across), which a piecewise quadratic ψ makes
            # exactly proportional: force = λ ∂W/∂e = λ k e and f = −ν e.
            stretch = 1.0 + SMALL_STRAIN
            pull = self.uniaxial_pull(angle, stretch)
            c, s = math.cos(angle), math.sin(angle)
            q = np.array([[c, -s], [s, c]])
            along, across = 0.5 * (stretch**2 - 1.0), 0.5 * float((q.T @ (pull.first_form - np.eye(2)) @ q)[1, 1])
            return pull.force_n_per_m / (stretch * along), -across / along
        c, s = math.cos(angle), math.sin(angle)
        compliance = np.linalg.inv(self.thickness * self.S)
        load = np.array([c * c, s * s, c * s])
        across = np.array([s * s, c * c, -c * s])
        along = float(load @ compliance @ load)
        return 1.0 / along, -float(across @ compliance @ load) / along

    def uniaxial_tension(self, axis: int, stretch: float) -> tuple[np.ndarray, float]:
        """Uniaxial tension along weft (``axis`` 0) or warp (1) with the other direction free:
        ``(I (2, 2), W)``. The free Green strain minimises W: for StVK ``E_other = −(s01/s_other) E``
        with ``E = (stretch² − 1)/2`` and ``W = (h/2) (s_axis − s01²/s_other) E²`` (J/m²), the
        free-width stiffness of the engineering constants; with a :class:`RidgeMembrane` it is the
        root of the transverse stress ``(∂ψ/∂ε)_other = 0`` (non-decreasing in E_other: ψ is
        convex). Needs a positive-definite ``S``."""
        if axis not in (0, 1):
            raise ValueError(f"axis must be 0 (weft) or 1 (warp), got {axis!r}")
        stretch = finite_number(stretch, "stretch")
        if stretch <= 0.0:
            raise ValueError(f"stretch must be positive, got {stretch!r}")
        self._require_positive_definite("uniaxial tension states", membrane=True, bending=False)
        along, other = (self.s00, self.s11) if axis == 0 else (self.s11, self.s00)
        strain = 0.5 * (stretch**2 - 1.0)
        free = -self.s01 / other * strain
        if self.nonlinear is None:
            diagonal = [0.0, 0.0]
            diagonal[axis], diagonal[1 - axis] = 1.0 + 2.0 * strain, 1.0 + 2.0 * free
            return np.diag(diagonal), 0.5 * self.thickness * (along - self.s01**2 / other) * strain**2

        def form(free_strain: float) -> np.ndarray:
            diagonal = [0.0, 0.0]
            diagonal[axis], diagonal[1 - axis] = 1.0 + 2.0 * strain, 1.0 + 2.0 * free_strain
            return np.diag(diagonal)

        def transverse_stress(free_strain: float) -> float:
            eps = np.zeros(3)
            eps[axis], eps[1 - axis] = strain, free_strain
            return float(self.membrane_stress(eps)[1 - axis])

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
        # W's exact Hessian h Vᵀ (∂²ψ/∂ε²) V (ε is linear in (f, γ): ε = ε(e, 0, 0) + V (f, γ)),
        # regularised by UNIAXIAL_REGULARISATION where it is singular (a ridge membrane can be flat
        # along a free strain), and steps halved until W falls, or the residual where W's change is
        # round-off (UNIAXIAL_ENERGY_ROUNDOFF; W is convex in them for a convex membrane), from the
        # small-strain Poisson contraction. A ridge membrane's ψ is piecewise quadratic: a Newton
        # step is exact within a piece, and the halving carries it across the kinks.
        # (E00, E11, 2 E01) of a symmetric strain matrix is the same map as κ's of II.
        across = _bending_voigt(q @ np.array([[0.0, 0.0], [0.0, 1.0]]) @ q.T)
        sheared = _bending_voigt(q @ np.array([[0.0, 1.0], [1.0, 0.0]]) @ q.T)
        V = np.stack([across, sheared], axis=1)

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
        free = np.array([max(-self.linear.uniaxial_stiffness(angle)[1] * strain, -0.5 * (1.0 - UNIAXIAL_WIDTH_MARGIN)),
                         0.0])
        # Residuals are judged against the stress the pulled strain makes in the stiffest
        # direction: a bias pull of a satin (s22 ~ 1e-5 s00) has a pulling stress below the
        # round-off of its weft and warp stresses.
        stiffest = self.S if self.nonlinear is None else self.nonlinear.largest_tangent(abs(strain))
        stiffness = self.thickness * max(float(np.abs(stiffest).max()), float(np.abs(self.S).max()))  # N/m
        scale = max(stiffness * abs(strain), 1e-300)
        regularisation = UNIAXIAL_REGULARISATION * stiffness
        for _ in range(UNIAXIAL_NEWTON_STEPS):
            if not admissible(free):
                break  # at the edge of the admissible widths: no free width balances the pull
            g = gradient(free)
            if np.abs(g).max() <= UNIAXIAL_STRESS_RTOL * scale:
                break
            hessian = self.thickness * V.T @ self.membrane_tangent(membrane_strain(first_form(free))) @ V
            direction = -np.linalg.solve(hessian + regularisation * np.eye(2), g)
            alpha, start, imbalance = 1.0, energy(free), float(np.abs(g).max())
            roundoff = UNIAXIAL_ENERGY_ROUNDOFF * abs(start)

            def accepted(trial: np.ndarray) -> bool:
                if not admissible(trial):
                    return False
                change = energy(trial) - start
                return change < -roundoff or (change <= roundoff
                                              and float(np.abs(gradient(trial)).max()) < imbalance)

            while alpha > UNIAXIAL_LEAST_STEP and not accepted(free + alpha * direction):
                alpha *= 0.5
            free = free + alpha * direction
            if alpha < 1.0:  # the model's step was too long: lean towards the gradient
                regularisation *= UNIAXIAL_REGULARISATION_GROWTH
            else:
                regularisation = max(regularisation / UNIAXIAL_REGULARISATION_GROWTH,
                                     UNIAXIAL_REGULARISATION * stiffness)
        if not admissible(free) or np.abs(gradient(free)).max() > UNIAXIAL_STRESS_RTOL * scale:
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
        ``dW/dI = (h/2) [[σ_0, σ_2], [σ_2, σ_1]]`` (J/m²) with ``σ`` :meth:`membrane_stress` and
        ``dW/dII = h³ [[m_0, m_2], [m_2, m_1]]`` (J/m) with ``m`` :meth:`bending_moment`.

        Returns:
            two arrays ``(2, 2)`` for ``(2, 2)`` inputs, else ``(n, 2, 2)``.
        """
        eps, kap, _ = self._strains(I, II)
        shape = np.broadcast_shapes(eps.shape, kap.shape)
        sigma = self.membrane_stress(eps)
        sigma = np.broadcast_to(sigma, shape)
        moment = np.broadcast_to(self.bending_moment(kap), shape)
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
        plus ``"nonlinear"`` (:meth:`RidgeMembrane.to_dict`) when the material has a strain-stiffening
        membrane (``membrane_pa`` is then its linear model) and ``"signed_bending_pa"``
        (:meth:`SignedBending.to_dict`) when it has a signed bending (``bending_pa`` is then its
        symmetric model)."""
        data = {
            "thickness_m": self.thickness,
            "membrane_pa": {name: getattr(self, name) for name in MEMBRANE_PARAMETERS},
            "bending_pa": {name: getattr(self, name) for name in BENDING_PARAMETERS},
        }
        if self.nonlinear is not None:
            data["nonlinear"] = self.nonlinear.to_dict()
        if self.signed_bending is not None:
            data["signed_bending_pa"] = self.signed_bending.to_dict()
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
        _check_keys(data, ("thickness_m", "membrane_pa", "bending_pa"), where, "", ("nonlinear", "signed_bending_pa"))
        fields = {"thickness": _json_number(data["thickness_m"], where, "thickness_m")}
        if "nonlinear" in data:
            fields["nonlinear"] = RidgeMembrane.from_dict(data["nonlinear"], where)
        if "signed_bending_pa" in data:
            fields["signed_bending"] = SignedBending.from_dict(data["signed_bending_pa"], where)
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

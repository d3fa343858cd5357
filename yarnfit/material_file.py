"""The material file: one owner for writing, reading, version-checking and rebuilding from it.

``yarnfit fit`` writes one JSON file per fabric, SI units, stable keys:

- ``yarnfit_version``;
- ``inputs``: ``fabric`` (name), ``fiber`` (name, density_kg_m3, young_min_pa, young_max_pa,
  breaking_strain, poisson, friction, source, and where known fineness_dtex,
  flexural_rigidity_nm2_per_tex2, torsional_rigidity_nm2_per_tex2, spinning), ``yarn`` (the
  construction as given: model, spinning, packing_fraction, twist_angle_deg and measured
  rigidities, null for defaults), ``pattern`` (named structure or file), ``family``,
  ``counts_per_m`` (``[ends, picks]`` or ``[courses, wales]``, null for a file used as written),
  ``areal_density_kg_m2`` (null likewise);
- ``yarn``: the yarn (:meth:`yarnfit.yarn.Yarn.to_dict`: ``model``, ``spinning``,
  ``linear_density_tex``, ``fibres_per_section``, ``packing_fraction``, ``twist_angle_deg``,
  ``radius_m``, ``tensile_rigidity_n``, ``hardening_n``, ``shear_rigidity_n``,
  ``bending_rigidity_nm2``, ``torsional_rigidity_nm2``, ``bending_vs_solid``, ``limits``), the
  fibre's ``young_modulus_pa`` (E_min), ``hardening_pa``, ``poisson``, ``density_kg_m3``,
  ``friction``, and ``shrink``, ``repeat_size_m``, ``yarn_length_per_area_m_per_m2``,
  ``areal_density_kg_m2`` (of the relaxed repeat) and the relaxation's ``converged``,
  ``iterations``, ``residual`` and ``worst_overlap``;
- ``shell``: ``thickness_m``, ``membrane_pa`` {s00, s01, s11, s22} (the linear model fitted to the
  samples), ``bending_pa`` {b00, b01, b11, b22} and, for the strain-stiffening membrane,
  ``nonlinear`` {``model`` ``"green-ridge"``, ``base_pa``, ``ridges``} (:class:`~yarnfit.shell.RidgeMembrane`,
  the whole membrane: :attr:`MaterialFile.shell` reads it back; a reader that knows only StVK reads
  the linear model; an earlier yarnfit's ``green-polynomial`` block is refused, naming the fix) and,
  for the signed bending, ``signed_bending_pa`` {b00_pos, b00_neg, b01, b11_pos, b11_neg, b22}
  (:class:`~yarnfit.shell.SignedBending`, the whole bending; ``bending_pa`` is then the symmetric
  fit beside it);
- ``engineering``: the small-strain constants of ``docs/design.md`` §3 (``weft_stretch_n_per_m``, …);
- ``fit``: the fit's quality (model, membrane, bending (``"signed"`` or ``"symmetric"``), parameters and standard errors, R² and relative RMS
  per family, the ``linear`` fit beside it (parameters and quality: :attr:`MaterialFile.linear_shell`),
  the strain range the stiffening was fitted over, the rest energies left out of the shell (the
  membrane's ``reference_energy_j_per_m2``, the bends' ``bending_reference_energy_j_per_m2``) and
  the residual stress when fitted, active bounds, weights, used and excluded samples);
- ``samples``: every sample — ``family``, ``parameter``, ``I``, ``II``, ``energy_density_j_m2``,
  ``converged``, ``residual`` {force, torque, penetration, energy_change}, ``iterations``,
  ``seconds``, ``stretch_share`` (of Ū in the yarns' stretch; absent or null: unknown),
  ``pull_slope_n_per_m`` and ``across_slope_n_per_m`` (uniaxial samples: dŪ/dE along and across the
  pull at the width found; absent or null: unknown), ``free_membrane_strain`` (bends: the
  membrane Green strains ``[E00, E11, E01]`` they were solved at, zero membrane force; absent or
  null: unknown), ``design_parameter`` (a sample taken short of the design's parameter, given here,
  where its loading path converged no further; absent or null: as designed) — including
  those that did not converge (excluded from the fit, never used);
- ``relaxed_repeat``: ``pyp``, the relaxed repeat as ``.pyp`` text (:meth:`RelaxedRepeat.relaxed_pattern
  <yarnfit.relax.RelaxedRepeat.relaxed_pattern>`: relaxed positions, the rest lengths they balance
  and the relaxed frames' directors, floats written to round trip), from which
  :meth:`MaterialFile.relaxed_repeat` rebuilds the repeat without relaxing from scratch;
- ``seconds``: wall time per stage.

The shell thickness is the relaxed repeat's: the span of the yarn centrelines across the fabric
plus one diameter. It only scales S and B; the engineering constants do not depend on it.

:class:`MaterialFile` is the only code that reads or writes it: :meth:`MaterialFile.from_fit` and
:meth:`~MaterialFile.write` for ``yarnfit fit``, :meth:`~MaterialFile.read` for everyone else, with
typed views of what a reader needs (the shell, the areal density, the fabric it was fitted for, the
relaxed repeat, the samples and the rest state the fit took out of them). Errors are one line starting with the file's path.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from . import __version__
from .fibers import OPTIONAL_FIBER_FIELDS, Fiber
from .jsonfile import read_json
from .outputs import write_atomically
from .checks import check_keys, finite_number
from .shell import PARAMETER_NAMES, ShellMaterial

if TYPE_CHECKING:  # the heavy stages are imported where they are used
    from .fabric import Fabric
    from .relax import RelaxedRepeat
    from .samples import SampleResult

__all__ = ["IncompatibleMaterial", "MaterialFile", "REQUIRED_KEYS", "fabric_from_inputs"]

# What a file must hold to be validated (older files lack the rest, which only reports read).
REQUIRED_KEYS = ("yarnfit_version", "inputs", "shell", "engineering")


class IncompatibleMaterial(ValueError):
    """A material file this version cannot use (missing keys, or written by another minor version)."""


class RestState(NamedTuple):
    """What a fit took out of every sample's Ū before the shell (:meth:`MaterialFile.rest_state`):
    the membrane samples' rest ``energy`` (J/m²), the membrane's ``residual_stress``
    (``{n0, n1, n2}`` N/m) and the bends' rest energy ``bending_energy`` (J/m²)."""

    energy: float
    residual_stress: dict[str, float]
    bending_energy: float


@dataclass(frozen=True, eq=False)
class MaterialFile:
    """A material file's decoded contents ``data`` and ``where`` they came from (a path, or
    ``"material"`` for data built in memory)."""

    data: dict
    where: str = "material"

    # -- writing ------------------------------------------------------------------------------

    @classmethod
    def from_fit(cls, fit) -> "MaterialFile":
        """The file of ``fit``, a :class:`~yarnfit.fabric_fit.FabricFit` (a fabric fitted end to
        end; see the module docstring)."""
        from .patterns import format_pyp

        fabric, relaxed, fiber = fit.fabric, fit.relaxed, fit.fabric.fiber
        residual = relaxed.residual
        data = {
            "yarnfit_version": __version__,
            "inputs": {
                "fabric": fabric.name,
                "fiber": {
                    "name": fiber.name,
                    "density_kg_m3": fiber.density_kg_m3,
                    "young_min_pa": fiber.young_min_pa,
                    "young_max_pa": fiber.young_max_pa,
                    "breaking_strain": fiber.breaking_strain,
                    "poisson": fiber.poisson,
                    "friction": fiber.friction,
                    "source": fiber.source,
                    **{key: getattr(fiber, key) for key in OPTIONAL_FIBER_FIELDS if getattr(fiber, key) is not None},
                },
                "yarn": fabric.yarn.to_dict(),
                "pattern": fabric.structure if fabric.structure is not None else str(fabric.pattern_file),
                "family": relaxed.pattern.family,
                "counts_per_m": None if fabric.uses_file_as_is else list(fabric.counts_per_m(relaxed.pattern)),
                "areal_density_kg_m2": fabric.areal_density,
            },
            "yarn": {
                **relaxed.yarn.to_dict(),
                "young_modulus_pa": fiber.young_min_pa,
                "hardening_pa": fiber.hardening_pa,
                "poisson": fiber.poisson,
                "density_kg_m3": fiber.density_kg_m3,
                "friction": fiber.friction,
                "shrink": relaxed.shrink,
                "repeat_size_m": [float(v) for v in relaxed.repeat_size],
                "yarn_length_per_area_m_per_m2": relaxed.yarn_length_per_area,
                "areal_density_kg_m2": relaxed.areal_density,
                "relaxation": {
                    "converged": relaxed.converged,
                    "iterations": relaxed.iterations,
                    "relaxations": relaxed.relaxations,
                    "residual": {"force": residual.force, "torque": residual.torque,
                                 "energy_change": residual.energy_change, "penetration": residual.penetration},
                    "worst_overlap": relaxed.penetration,
                    "seconds": relaxed.seconds,
                },
            },
            "shell": fit.material.to_dict(),
            "engineering": fit.material.engineering(),
            "fit": {**fit.fit.quality_dict(), "stretch_range": fit.ranges.stretch,
                    "curvature_range_per_m": fit.ranges.curvature, "sample_friction": fit.sample_friction},
            "samples": [s.to_dict() for s in fit.samples],
            "seconds": dict(fit.seconds),
            "relaxed_repeat": {"pyp": format_pyp(relaxed.relaxed_pattern())},
        }
        return cls(data, "material")

    def write(self, path: str | os.PathLike) -> Path:
        """Write the file (directories created; strict JSON; whole or not at all: a temporary file
        renamed over ``path``); returns its path."""
        return write_atomically(path, json.dumps(self.data, indent=2, allow_nan=False) + "\n")

    # -- reading ------------------------------------------------------------------------------

    @classmethod
    def read(cls, source: "str | os.PathLike | Mapping | MaterialFile") -> "MaterialFile":
        """The file at ``source`` (or its decoded contents, a mapping; a file already read is
        returned as it is). ValueError ``<path>: ...`` for an unreadable file, invalid JSON or
        anything but a JSON object."""
        if isinstance(source, MaterialFile):
            return source
        if isinstance(source, Mapping):
            return cls(dict(source), "material")
        where, data = read_json(source, "material file")
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a JSON object (a `yarnfit fit` material file), "
                             f"got a {type(data).__name__}")
        return cls(data, where)

    def check_version(self) -> None:
        """:class:`IncompatibleMaterial` unless the file has :data:`REQUIRED_KEYS` and was written
        by this minor version of yarnfit (the format follows the minor version)."""
        missing = [key for key in REQUIRED_KEYS if key not in self.data]
        if missing:
            raise IncompatibleMaterial(f"{self.where}: missing key{'s' if len(missing) > 1 else ''} "
                                       f"{', '.join(missing)} (write it with `yarnfit fit`)")
        version = self.data["yarnfit_version"]
        if not isinstance(version, str) or version.split(".")[:2] != __version__.split(".")[:2]:
            raise IncompatibleMaterial(f"{self.where}: written by yarnfit {version!r}, this is {__version__}: "
                                       "refit it with `yarnfit fit` (the file format follows the minor version)")

    @property
    def shell(self) -> ShellMaterial:
        """The fitted shell (``shell``); ValueError naming the file and the key at fault."""
        if "shell" not in self.data:
            raise ValueError(f"{self.where}: missing key 'shell' (the fitted shell material)")
        return ShellMaterial.from_dict(self.data["shell"], f"{self.where}: shell")

    @property
    def linear_shell(self) -> ShellMaterial:
        """The linear (StVK) fit from the same samples: ``fit.linear.parameters_pa`` with the
        shell's thickness. A file without it (written before the strain-stiffening membrane) has a
        linear shell already: its ``shell``. The ``shell.nonlinear`` and ``shell.signed_bending_pa``
        blocks are not read, so a file of an earlier membrane model still gives its linear fit.
        ValueError naming the key at fault."""
        data = self._block("shell")
        shell = ShellMaterial.from_dict({k: v for k, v in data.items() if k not in ("nonlinear", "signed_bending_pa")},
                                        f"{self.where}: shell")
        linear = self._block("fit").get("linear")
        if linear is None:
            return shell.linear
        where = f"{self.where}: fit.linear"
        if not isinstance(linear, Mapping) or not isinstance(linear.get("parameters_pa"), Mapping):
            raise ValueError(f"{where}: expected an object with 'parameters_pa'")
        parameters = linear["parameters_pa"]
        check_keys(parameters, PARAMETER_NAMES, where, prefix="parameters_pa.")
        values = {}
        for key in PARAMETER_NAMES:
            value = parameters[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{where}: parameters_pa.{key} must be a number, got {value!r}")
            values[key] = float(value)
        try:
            return ShellMaterial(shell.thickness, **values)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None

    @property
    def sample_friction(self) -> float:
        """The friction coefficient the membrane samples were loaded with (``fit.sample_friction``:
        0 for the paper's frictionless minimisers, and for a file written before it was kept)."""
        value = self._block("fit").get("sample_friction", 0.0)
        value = finite_number(value, f"{self.where}: fit.sample_friction")
        if value < 0.0:
            raise ValueError(f"{self.where}: fit.sample_friction must be non-negative, got {value!r}")
        return value

    def samples(self) -> "list[SampleResult]":
        """The yarn-level samples (``samples``) as :class:`~yarnfit.samples.SampleResult`, in file
        order, those that did not converge included (their Ū NaN where none was reached; no node
        positions). ValueError naming the file if it has none (written before yarnfit kept them, or
        not by ``yarnfit fit``) or an entry is malformed."""
        from .samples import SampleResult

        samples = self.data.get("samples")
        if not isinstance(samples, list) or not samples:
            raise ValueError(f"{self.where}: no yarn-level samples (key 'samples'; write the file with `yarnfit fit`)")
        return [SampleResult.from_dict(sample, f"{self.where}: samples[{k}]") for k, sample in enumerate(samples)]

    def rest_state(self) -> RestState:
        """What the fit took out of every sample's Ū before the shell (``fit.reference_energy_j_per_m2``,
        ``fit.residual_stress.membrane_n_per_m`` and ``fit.bending_reference_energy_j_per_m2``;
        :func:`yarnfit.fit.shell_energy_of` subtracts them); zeros for a file written before they
        were fitted, the membrane's rest energy for the bends' in one written before bends were
        solved at zero membrane force."""
        fit = self._block("fit")
        energy = fit.get("reference_energy_j_per_m2", 0.0)
        bending = fit.get("bending_reference_energy_j_per_m2", energy)
        stress = fit.get("residual_stress", {})
        stress = stress.get("membrane_n_per_m", {}) if isinstance(stress, dict) else {}
        where = f"{self.where}: fit"
        if not isinstance(stress, dict):
            raise ValueError(f"{where}.residual_stress.membrane_n_per_m must be an object, got {stress!r}")
        return RestState(finite_number(energy, f"{where}.reference_energy_j_per_m2"),
                         {key: finite_number(value, f"{where}.residual_stress.membrane_n_per_m.{key}")
                          for key, value in stress.items()},
                         finite_number(bending, f"{where}.bending_reference_energy_j_per_m2"))

    @property
    def name(self) -> str:
        """The fabric's name (``inputs.fabric``), else the file's stem."""
        inputs = self._block("inputs")
        name = inputs.get("fabric")
        return name if isinstance(name, str) and name.strip() else Path(self.where).stem

    @property
    def family(self) -> str | None:
        """The pattern family the fabric was fitted with (``inputs.family``: woven, knit, other),
        or None when the file does not say."""
        family = self._block("inputs").get("family")
        return family if isinstance(family, str) else None

    def areal_density(self) -> tuple[float, str] | None:
        """``(kg/m², key)`` of the fabric: ``inputs.areal_density_kg_m2`` if the fabric was given
        one, else the relaxed repeat's ``yarn.areal_density_kg_m2``; ``None`` if neither is there."""
        for key in ("inputs", "yarn"):
            value = self._block(key).get("areal_density_kg_m2")
            if value is not None:
                return value, f"{key}.areal_density_kg_m2"
        return None

    def fabric(self) -> "Fabric":
        """The :class:`~yarnfit.fabric.Fabric` the material was fitted for (``inputs``)."""
        return fabric_from_inputs(self.data.get("inputs"), self.where)

    def relaxed_or_relaxed_again(self, progress: Callable[[str], None] | None = None) -> "RelaxedRepeat":
        """:meth:`relaxed_repeat`, or for a file written before it was kept the fabric of its
        ``inputs`` relaxed again (said through ``progress``)."""
        relaxed = self.relaxed_repeat()
        if relaxed is None:
            from .relax import relax

            fabric = self.fabric()
            if progress is not None:
                progress(f"{self.where} keeps no relaxed repeat (written before yarnfit kept it): relaxing "
                         f"{fabric.name} again")
            relaxed = relax(fabric)
        return relaxed

    def relaxed_repeat(self) -> "RelaxedRepeat | None":
        """The relaxed repeat the material was fitted from (``relaxed_repeat``), or ``None`` for a
        file written before it was kept. Rebuilt by relaxing the stored repeat as written (shrink
        1): it starts at its own equilibrium and only the contact multipliers (not kept) are found
        again, ~15 Newton iterations; positions come back to ~1e-10 of the radius."""
        block = self.data.get("relaxed_repeat")
        if block is None:
            return None
        from .patterns import parse_pyp
        from .relax import relax_pattern

        if not isinstance(block, dict) or not isinstance(block.get("pyp"), str):
            raise ValueError(f"{self.where}: relaxed_repeat must be an object with the key 'pyp' (.pyp text)")
        fabric = self.fabric()
        pattern = parse_pyp(block["pyp"], fabric.name, f"{self.where}: relaxed_repeat.pyp")
        return relax_pattern(pattern, fabric.fiber, shrink=1.0, name=fabric.name, yarn=fabric.yarn)

    def _block(self, key: str) -> dict:
        block = self.data.get(key)
        return block if isinstance(block, dict) else {}


def fabric_from_inputs(inputs, where: str = "material") -> "Fabric":
    """The :class:`~yarnfit.fabric.Fabric` a material file's ``inputs`` block describes."""
    from .fabric import Fabric, named_patterns
    from .yarn import YarnConstruction

    if not isinstance(inputs, dict):
        raise ValueError(f"{where}: missing 'inputs' (the fabric the material was fitted for)")
    try:
        fiber = inputs["fiber"]
        optional = ("source",) + OPTIONAL_FIBER_FIELDS
        fiber = Fiber(**{k: fiber[k] for k in ("name", "density_kg_m3", "young_min_pa", "young_max_pa",
                                                        "breaking_strain", "poisson", "friction")},
                              **{k: fiber[k] for k in optional if k in fiber})
        # Files written before the fibre-assembly yarn (no inputs.yarn) were fitted with the paper's
        # solid rod: rebuild them with it.
        yarn = (YarnConstruction.from_dict(inputs["yarn"], f"{where}: inputs.yarn") if "yarn" in inputs
                else YarnConstruction(model="solid"))
        pattern = inputs["pattern"]
        counts = inputs.get("counts_per_m")
        structure = pattern if pattern in named_patterns() else None
        return Fabric(name=str(inputs.get("fabric") or "fabric"), fiber=fiber, structure=structure,
                      areal_density=inputs.get("areal_density_kg_m2"),
                      counts=None if counts is None else (float(counts[0]), float(counts[1])),
                      pattern_file=None if structure is not None else pattern, yarn=yarn)
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{where}: inputs: cannot rebuild the fabric ({exc!r})") from None

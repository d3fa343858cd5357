"""The yarn engine: Cosserat rods (points plus one quaternion frame per edge) with
stretch–shear and bend–twist energies, yarn–yarn contact with friction, an XPBD time stepper and a
quasi-static Newton solver that stops on residuals.

Typical use::

    from yarnfit.engine import Rod, RodMaterial, RodModel, RodState, Loads, QuasiStaticSolver

    model = RodModel.from_rods([Rod(points, radius=1e-4, material=RodMaterial(3e9), pinned_nodes=[0])])
    loads = Loads.zeros(model, gravity=(0, 0, -9.81))
    result = QuasiStaticSolver(model).solve(RodState.from_model(model), loads)
"""

from .energy import EnergyTerms, energy, energy_gradient
from .model import Rod, RodMaterial, RodModel, RodSection, aligned_frames, parallel_transport_frames, straight_points
from .quasistatic import (
    ConvergenceWarning,
    LinearConstraints,
    Progress,
    QuasiStaticOptions,
    QuasiStaticResult,
    QuasiStaticSolver,
    Residual,
)
from .state import Loads, RodState
from .xpbd import XPBDOptions, XPBDSolver

__all__ = [
    "ConvergenceWarning",
    "EnergyTerms",
    "LinearConstraints",
    "Loads",
    "Progress",
    "QuasiStaticOptions",
    "QuasiStaticResult",
    "QuasiStaticSolver",
    "Residual",
    "Rod",
    "RodMaterial",
    "RodSection",
    "RodModel",
    "RodState",
    "XPBDOptions",
    "XPBDSolver",
    "aligned_frames",
    "energy",
    "energy_gradient",
    "parallel_transport_frames",
    "straight_points",
]

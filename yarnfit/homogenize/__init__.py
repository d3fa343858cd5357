"""Homogenization (paper §4.5, phase 2): the relaxed repeat tiled over a deformed mid-surface.

A sample is a pair of constant fundamental forms ``(I, II)`` (``I`` 2×2 SPD, ``II`` 2×2 symmetric,
1/m; the rest surface is flat with ``I = Id``). Every node of the relaxed repeat has reference
coordinates ``X`` in the fabric plane (measured from the repeat's centre) and a height ``h`` above
its mid-plane; it is placed at ``x = φ(X) + h n(X) + ũ`` on a mid-surface ``φ`` whose fundamental
forms at ``X = 0`` are ``(I, II)``, with ``R(X) = [∂φ polar rotation | n]`` the surface frame:

- ``φ(X) = β(S X)``, ``S = I^{1/2}`` (symmetric: a pure membrane sample turns nothing), and ``β``
  the bent plane with second fundamental form ``II' = S⁻¹ II S⁻¹``: a **circular cylinder** when
  ``II'`` is singular (single, bias and any other developable bend: exact, its metric is ``I``
  everywhere), otherwise a quadric ``(Y, ½ Yᵀ II' Y)`` with cubic corrections in the plane. A
  saddle's Gauss curvature K cannot live on a flat metric: the corrections cancel the quadric's
  own metric strain (``κ² Y²``) and leave the Gauss defect ``K Y² / 4`` per axis, which the saddle
  curvatures keep small (see :func:`sample_design`).
- Periodicity (``C_RVE_Γ``): the image of node i in tile T is where its co-rotated fluctuation
  ``Rᵀ ũ`` is the same at ``X_i + T``: ``Q x + c`` with ``Q = R(X_i + T) R(X_i)ᵀ``. These per-node
  rigid maps (:class:`~yarnfit.engine.tiling.CurvedTiling`) carry ghost-edge ends, frames across
  tile borders (so the twist across a border is the twist of a real joint: the paper's matching
  end twist, and no net twist can build up from tile to tile) and contacts with every image.
- ``C_RVE``: per yarn, ``Σ_j R_jᵀ ũ_j = 0`` — linear in the positions since ``R_j`` is fixed.

The quasi-static solver then minimises the yarn energy; ``Ū = U / (p_x p_y)`` (J/m² of reference
area) with its residual is the sample's result. Samples are independent and run in parallel.

Modules, in the order data flows through them: :mod:`.surface` (the repeat on the mid-surface),
:mod:`.equilibrium` (one solve, its continuation and warm starts, Ū's slope along a strain),
:mod:`.search` (the quasi-Newton of the free strains), :mod:`.uniaxial` and :mod:`.bias` (the
free-strain searches of the uniaxial samples), :mod:`.bend` (the bends at zero membrane force),
:mod:`.sample` (any sample, the default ranges), :mod:`.pull` (the
periodic pull a cut strip converges to), :mod:`.frictional` (the same pull along a load path
with the fibre's friction, as a strip is pulled), :mod:`.loading` (the membrane samples along
such paths, for a shell fitted to the fabric's loading response: ``yarnfit fit --friction``) and
:mod:`.groups` (many samples in parallel, grouped into paths and single samples).
"""

from .equilibrium import MAX_ITERATIONS
from .frictional import frictional_periodic_bias_pull, frictional_periodic_pull, periodic_pulls_along
from .groups import group_tasks, sample_groups, solve_group, solve_loading_samples, solve_samples
from .loading import loading_path_samples
from .pull import PeriodicPull, periodic_bias_pull, periodic_pull
from .sample import MAX_TURN_PER_REPEAT, default_ranges, solve_sample
from .surface import SurfaceMap, TiledRepeat, tile_repeat, transfer_fluctuation

__all__ = [
    "MAX_ITERATIONS",
    "MAX_TURN_PER_REPEAT",
    "PeriodicPull",
    "SurfaceMap",
    "TiledRepeat",
    "default_ranges",
    "frictional_periodic_bias_pull",
    "frictional_periodic_pull",
    "group_tasks",
    "loading_path_samples",
    "periodic_bias_pull",
    "periodic_pull",
    "periodic_pulls_along",
    "sample_groups",
    "solve_group",
    "solve_sample",
    "solve_loading_samples",
    "solve_samples",
    "tile_repeat",
    "transfer_fluctuation",
]

"""A periodic test model on a random curved tiling (shared by the gradient and Hessian tests).

Two yarns cross a 4 mm × 3 mm tile: a wavy weft yarn closing into the next tile along x, and a
warp yarn along y that crosses the tile border mid-way (its chain has a ghost edge inside). Every
node reaches its images in the four neighbouring tiles by its own random rigid map, so ghost-edge
ends are rotated and frames are turned across tile borders: the transforms the kernels must chain.
"""

import numpy as np
from scipy.spatial.transform import Rotation

from yarnfit.engine import Rod, RodMaterial, RodModel
from yarnfit.engine.tiling import CurvedTiling, retile

LATTICE = np.array([[4e-3, 0.0, 0.0], [0.0, 3e-3, 0.0]])


def curved_model(seed: int = 0, reach: int = 1, turn: float = 0.3, jitter: float = 2e-4) -> RodModel:
    """The model with maps for every tile within ``reach``: rotations of ~``turn`` rad and
    translations ``jitter`` (m) off the lattice."""
    rng = np.random.default_rng(seed)
    material = RodMaterial(2e8, 0.35, 1000.0, hardening_tension=5e8, hardening_compression=2e8)
    x = np.linspace(0.0, 4e-3, 8, endpoint=False)
    weft = np.column_stack([x, 1e-3 + 2e-4 * np.sin(2 * np.pi * x / 4e-3), 1e-4 * np.cos(2 * np.pi * x / 4e-3)])
    weft_tiles = np.zeros((8, 2), dtype=int)
    weft_tiles[-1] = (1, 0)
    # Warp yarn: starts at y = 2 mm, crosses the border at its 3rd edge, comes back inside.
    y = np.linspace(2e-3, 5e-3, 6, endpoint=False)
    warp = np.column_stack([np.full(6, 2.5e-3), np.where(y < 3e-3, y, y - 3e-3), -1e-4 * np.sin(y * 2e3)])
    warp_tiles = np.zeros((6, 2), dtype=int)
    warp_tiles[np.flatnonzero(y < 3e-3)[-1]] = (0, 1)
    rods = [Rod(weft, 2e-4, material, closed=True, tile_offsets=weft_tiles),
            Rod(warp, 2e-4, material, closed=True, tile_offsets=warp_tiles)]
    flat = RodModel.from_rods(rods, lattice=LATTICE)
    offsets = np.arange(-reach, reach + 1)
    images = np.array([(0, 0)] + [(i, j) for i in offsets for j in offsets if (i, j) != (0, 0)])
    n, k = flat.n_nodes, len(images)
    rotation = Rotation.from_rotvec(turn * rng.standard_normal((n * k, 3))).as_matrix().reshape(n, k, 3, 3)
    translation = (images @ LATTICE)[None] + jitter * rng.standard_normal((n, k, 3))
    rotation[:, 0], translation[:, 0] = np.eye(3), 0.0
    return retile(flat, CurvedTiling(images, rotation, translation), LATTICE)

"""Acceptance figures of the yarnfit.shell plugin on the three kinds of mesh a scene or a user
builds (issues 5 and 15): a regular grid with one diagonal per cell, criss-cross cells (both
diagonals around a centre vertex) and an unstructured panel mesh (scenes.panel_mesh: Delaunay on a
jittered lattice, edges in every direction).

1. Patch tests: a 0.16 × 0.08 m strip held in the uniaxial state of the shell law at 0.1 % strain
   along weft, warp and bias (the plugin's weft turned by 0, 90°, 45°): the force per width on the
   pulled end against the law's, and the largest force on any other vertex against the end's
   force per vertex (linear triangles carry a uniform strain exactly on any mesh).
2. Bending: a 0.1 × 0.02 m strip (membrane made negligible) wrapped around a cylinder of curvature
   20 /m along and across it and on the bias, at cells of 1/32 of its length: energy per area
   against ½ bending κ² (the free ends' missing hinges cost ~1/n).
3. Clamped strips (locking): the 8 × 5 cm FAB strip's clamped stiffness (validate.stretch's
   linear solve, constant-strain triangles: the plugin's membrane="triangle") of a knit along its courses and
   of a woven cut on the bias, at the drapes' 1.5 cm cells, against a fine criss-cross mesh of
   1 mm cells.
4. The same clamped strips with node-smoothed strains (validate.stretch's solve with
   ``smoothing="node"``: the plugin's default membrane="node", whose clamped strip equals this solve
   to 1e-5, tests/test_plugin_mechanics.py).

Run: python validation/plugin_acceptance.py [--knit MATERIAL.json] [--woven MATERIAL.json]
(default: the cotton-jersey and cotton-twill presets, fitted first, ~20 s).
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import test_plugin_mechanics as mechanics  # noqa: E402
from test_plugin_mechanics import MESH_KINDS, strip_mesh  # noqa: E402
from yarnfit.validate.stretch import clamped_strip_stiffness  # noqa: E402

PATCH_STRAIN = 1e-3
BENDING_CURVATURE = 20.0  # 1/m: about 115° over the 0.1 m strip
BENDING_CELLS = 32  # cells along the strip
DRAPE_CELL = 0.015  # m, the drapes' (validate.drape RESOLUTION at 0.3 m)
FINE_CELL = 0.001  # m


def patch(kind: str, angle: float) -> tuple[float, float]:
    return mechanics.uniform_patch(kind, angle, PATCH_STRAIN)


def bending(kind: str, direction: str) -> float:
    """Relative error of the bent strip's energy per area against ½ bending κ²."""
    return mechanics.bent_strip_error(kind, direction, BENDING_CELLS, curvature=BENDING_CURVATURE)


def clamped(shell, kind: str, angle: float, cell: float, smoothing: str = "triangle") -> float:
    points, triangles = strip_mesh(kind, 0.08, 0.05, cell)
    return clamped_strip_stiffness(shell, points, triangles, angle, smoothing)


def preset_shell(name: str):
    import tempfile

    from yarnfit.fabric import Fabric
    from yarnfit.fabric_fit import fit_fabric
    from yarnfit.mujoco.scenes import ClothMaterial

    with warnings.catch_warnings(), tempfile.TemporaryDirectory() as folder:
        warnings.simplefilter("ignore")
        return ClothMaterial.from_file(fit_fabric(Fabric.preset(name)).write(Path(folder) / f"{name}.json")).shell


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--knit", help="material file of a knit (default: the cotton-jersey preset, fitted)")
    parser.add_argument("--woven", help="material file of a woven (default: the cotton-twill preset, fitted)")
    args = parser.parse_args()
    from yarnfit.mujoco.scenes import ClothMaterial

    print(f"1. patch tests at {PATCH_STRAIN:g} strain, 1 cm cells: end force per width against the law; "
          "largest other vertex force over the end's per vertex")
    for kind in MESH_KINDS:
        cells = [f"{d} {e:+.1e} / {o:.1e}" for d, a in (("weft", 0.0), ("warp", math.pi / 2), ("bias", math.pi / 4))
                 for e, o in [patch(kind, a)]]
        print(f"  {kind:>10}: " + "   ".join(cells))
    print(f"\n2. cylinder bending at {BENDING_CURVATURE:g} /m, cells 1/{BENDING_CELLS} of the 0.1 m strip: "
          "energy per area against ½ bending κ²")
    for kind in MESH_KINDS:
        print(f"  {kind:>10}: " + "   ".join(f"{d} {bending(kind, d):+.2%}" for d in ("weft", "warp", "bias")))
    knit = ClothMaterial.from_file(args.knit).shell if args.knit else preset_shell("cotton-jersey")
    woven = ClothMaterial.from_file(args.woven).shell if args.woven else preset_shell("cotton-twill")
    print(f"\n3. clamped 8 × 5 cm strips at {DRAPE_CELL * 100:g} cm cells against a fine criss-cross mesh "
          f"({FINE_CELL * 1e3:g} mm): stiffness ratio")
    for label, shell, angle in (("knit along its courses", knit, 0.0), ("woven on the bias", woven, math.pi / 4)):
        fine = clamped(shell, "crisscross", angle, FINE_CELL)
        ratios = "   ".join(f"{kind} {clamped(shell, kind, angle, DRAPE_CELL) / fine:.3f}" for kind in MESH_KINDS)
        print(f"  {label:>22} (fine {fine:.4g} N/m): {ratios}")
    print(f"\n4. the same with node-smoothed strains (the plugin's default membrane), at {DRAPE_CELL * 100:g} cm "
          "and 1.25 cm cells")
    for label, shell, angle in (("knit along its courses", knit, 0.0), ("woven on the bias", woven, math.pi / 4)):
        fine = clamped(shell, "crisscross", angle, FINE_CELL)
        ratios = "   ".join(f"{kind} {clamped(shell, kind, angle, cell, 'node') / fine:.3f}"
                           for cell in (DRAPE_CELL, 0.0125) for kind in MESH_KINDS)
        print(f"  {label:>22}: {ratios}")


if __name__ == "__main__":
    main()

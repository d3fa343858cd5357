"""Issue 5 acceptance figures of the yarnfit.shell plugin in MuJoCo: patch tests (clamp force and
Poisson contraction against the shell law) and bending into a cylinder (energy against
½ bending κ², under mesh refinement). The same computations as tests/test_plugin_mechanics.py,
printed. Run: python validation/plugin_acceptance.py"""

import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import test_plugin_mechanics as mechanics  # noqa: E402
from fabric_shell import FABRIC  # noqa: E402


def main() -> None:
    print(f"patch test at strain {mechanics.STRAIN:g} (relative errors against the small-strain shell law)")
    print(f"{'direction':>9} {'N/m measured':>13} {'N/m law':>10} {'error':>9} {'poisson':>8} {'law':>7} {'error':>9}")
    for direction, angle in (("weft", 0.0), ("warp", math.pi / 2), ("bias", math.pi / 4)):
        tension, contraction = mechanics.patch_equilibrium(angle, mechanics.STRAIN)
        stiffness, poisson = FABRIC.uniaxial_stiffness(angle)
        measured_poisson = (1 - contraction) / mechanics.STRAIN
        print(f"{direction:>9} {tension / mechanics.STRAIN:13.2f} {stiffness:10.2f} {tension / mechanics.STRAIN / stiffness - 1:+9.2e}"
              f" {measured_poisson:8.4f} {poisson:7.4f} {measured_poisson / poisson - 1:+9.2e}")
    print("\nbending a 0.1 m x 0.02 m strip into a cylinder of curvature 20 /m (energy per area against ½ B κ²)")
    print(f"{'direction':>9} " + " ".join(f"{f'{n} cells':>10}" for n in (8, 16, 32, 64)))
    for direction, axis, angle in (("weft", 0, 0.0), ("warp", 1, 0.0), ("bias", 0, math.pi / 4)):
        expected = 0.5 * FABRIC.engineering()[f"bending_{direction}_nm"] * 20.0**2
        errors = []
        for cells in (8, 16, 32, 64):
            count, spacing = [3, 3], [0.01, 0.01]
            count[axis], spacing[axis] = cells + 1, 0.1 / cells
            model = mechanics.sheet(FABRIC, count, spacing, angle)
            errors.append(mechanics.bending_energy(model, 20.0, axis) / (0.1 * 0.02) / expected - 1)
        print(f"{direction:>9} " + " ".join(f"{e:+10.2e}" for e in errors))


if __name__ == "__main__":
    main()

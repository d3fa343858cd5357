"""The figures issues 4 and 14 ask for, beside the tests that assert them
(tests/test_homogenize.py, tests/test_fit.py):

    python validation/fit_acceptance.py

- analytic end to end: one straight weft yarn per repeat (spacing d = 3r, linear fibre, breaking
  strain 0.1 and 0.4, solid and fibre-assembly yarns) against EA/d and EI/d (the solid rod's
  E π r²/d and E π r⁴/(4d)), and the ratios of warp stretch, shear and warp bending to them;
- invariance: Ū of the undeformed sample against a 1 % weft stretch; weft/warp constants of a
  square plain weave; stretch and bending at 150 and 250 g/m² at fixed counts.
"""

from __future__ import annotations

import warnings

import numpy as np

from yarnfit.fabric import Fabric
from yarnfit.fit import fit_shell
from yarnfit.homogenize import default_ranges, solve_sample, solve_samples
from yarnfit.fabric_fit import DEFAULT_LEVELS, fit_fabric, shell_thickness
from yarnfit.fibers import Fiber, get_fiber
from yarnfit.patterns import YarnPattern
from yarnfit.relax import relax_pattern
from yarnfit.samples import Family, SampleSpec, identity_sample, sample_design
from yarnfit.yarn import YarnConstruction


def analytic() -> None:
    """Issue 14's exact case: one straight weft yarn per repeat of a linear fibre, for breaking
    strains 0.1 and 0.4 (the default design samples up to them) and both yarn models, the fitted
    weft stretch and bending against the yarn's EA/d and EI/d (the solid rod's E π r²/d and
    E π r⁴/(4d)); the paper's fit model, as `tests/test_homogenize.py` (no warp bending here, so
    b01 is not identifiable)."""
    radius, spacing, young = 1e-4, 3e-4, 2e9
    nodes = np.linspace(0.0, 2e-3, 16, endpoint=False)
    yarn = np.column_stack([nodes, np.full_like(nodes, 0.5 * spacing), np.zeros_like(nodes)])
    repeat = YarnPattern.from_yarns("straight", "woven", (2e-3, spacing), radius, [(yarn, (1, 0))])
    for model in ("solid", "fibre-assembly"):
        for breaking_strain in (0.1, 0.4):
            linear = Fiber(name="linear", density_kg_m3=1000.0, young_min_pa=young, young_max_pa=young,
                           breaking_strain=breaking_strain, poisson=0.3, friction=0.2, fineness_dtex=2.0,
                           flexural_rigidity_nm2_per_tex2=0.5e-9, torsional_rigidity_nm2_per_tex2=0.2e-9)
            relaxed = relax_pattern(repeat, linear, shrink=1.0, yarn=YarnConstruction(model=model))
            results = solve_samples(relaxed, sample_design(default_ranges(relaxed), DEFAULT_LEVELS), workers=1)
            eng = fit_shell(results, shell_thickness(relaxed), model="paper").material.engineering()
            stretch = relaxed.yarn.tensile_rigidity_n / spacing
            bending = relaxed.yarn.bending_rigidity_nm2 / spacing
            print(f"straight yarns, {model} yarn, breaking strain {breaking_strain:g} "
                  f"({sum(r.converged for r in results)}/{len(results)} samples converged)")
            print(f"  weft stretch   {eng['weft_stretch_n_per_m']:.6g} N/m vs EA/d = {stretch:.6g} "
                  f"({100 * (eng['weft_stretch_n_per_m'] / stretch - 1):+.3f} %)")
            print(f"  weft bending   {eng['bending_weft_nm']:.6g} N·m vs EI/d = {bending:.6g} "
                  f"({100 * (eng['bending_weft_nm'] / bending - 1):+.3f} %)")
            print(f"  warp stretch / weft {eng['warp_stretch_n_per_m'] / stretch:.3g}, shear / weft stretch "
                  f"{eng['shear_n_per_m'] / stretch:.3g}, warp bending / weft {eng['bending_warp_nm'] / bending:.3g}")


def invariance() -> None:
    def plain(gsm):
        return Fabric(name="plain", fiber=get_fiber("cotton"), structure="plain", areal_density=gsm * 1e-3,
                      counts=(2500.0, 2500.0))

    fits = {gsm: fit_fabric(plain(gsm)) for gsm in (150.0, 200.0, 250.0)}
    relaxed = fits[200.0].relaxed
    zero = solve_sample(relaxed, identity_sample())
    one = solve_sample(relaxed, SampleSpec.at(Family.WEFT_STRETCH, 0.01))
    print(f"undeformed sample: Ū = {zero.energy_density:.3g} J/m² (residual {zero.residual}); 1 % weft stretch "
          f"Ū = {one.energy_density:.4g} J/m²; ratio {zero.energy_density / one.energy_density:.2g}")
    eng = fits[200.0].material.engineering()
    for weft, warp in (("weft_stretch_n_per_m", "warp_stretch_n_per_m"), ("bending_weft_nm", "bending_warp_nm")):
        print(f"square plain weave 200 g/m²: {weft} {eng[weft]:.6g}, {warp} {eng[warp]:.6g} "
              f"({100 * (eng[warp] / eng[weft] - 1):+.2f} %)")
    for gsm, fitted in fits.items():
        e = fitted.material.engineering()
        print(f"plain weave 25×25/cm at {gsm:g} g/m² (radius {1e6 * fitted.relaxed.radius:.1f} µm): weft stretch "
              f"{e['weft_stretch_n_per_m']:.5g} N/m, warp {e['warp_stretch_n_per_m']:.5g} N/m, bending weft "
              f"{e['bending_weft_nm']:.4g} N·m, warp {e['bending_warp_nm']:.4g} N·m")


if __name__ == "__main__":  # samples run in forked worker processes
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        analytic()
        invariance()

"""The paper's comparisons (§5) on the five presets (issue 6, item 7); prints the figures and
writes them to ``<logs>/paper_checks.json``.

    python validation/paper_checks.py [--materials DIR] [--logs logs]

(a) bias strips of each preset against its weft and warp strips (quick 8 × 5 strips; the wovens
    must be softer on the bias); (b) cotton jersey as labelled and with 1.5 times thicker yarns;
(c) cotton jersey's pattern, density and counts in cotton, wool and polyester, dropped on the
sphere. ``--materials`` holds ``<preset>.json`` files from ``yarnfit fit``; missing ones are fitted
there first.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from yarnfit.fabric import PRESETS, Fabric, named_patterns
from yarnfit.mujoco.scenes import ClothMaterial
from yarnfit.validate.paper import bias_softness, compare_fibre_drapes, compare_thickness
from yarnfit.validate.stretch import run_stretch


def preset_material(folder: Path, preset: str) -> ClothMaterial:
    path = folder / f"{preset}.json"
    if not path.is_file():
        from yarnfit.fabric_fit import fit_fabric

        print(f"fitting {preset} -> {path}", flush=True)
        fit_fabric(Fabric.preset(preset)).write(path)
    return ClothMaterial.from_file(path)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--materials", default="logs/materials", help="folder of <preset>.json material files")
    parser.add_argument("--logs", default="logs", help="where paper_checks.json goes")
    args = parser.parse_args()
    folder = Path(args.materials)
    folder.mkdir(parents=True, exist_ok=True)
    out = {"bias_softness": {}}
    start = time.perf_counter()

    print("(a) bias force over the weaker of weft and warp, 8 x 5 strips (quick mesh)")
    for preset in PRESETS:
        soft = bias_softness(run_stretch(preset_material(folder, preset), quick=True).summary())["8x5"]
        out["bias_softness"][preset] = soft
        ratios = ", ".join(f"{e:.3g}: " + ("undefined" if r is None else f"{r:.3f}")
                           for e, r in zip(soft["strain"], soft["bias_over_weakest_axis"]))
        print(f"  {preset:17s} softer on the bias: {str(soft['bias_softer']):5s}  (strain: ratio) {ratios}")

    print("(b) cotton-jersey with 1.5 times thicker yarns, 8 x 5 strips (quick mesh)")
    thickness = compare_thickness(Fabric.preset("cotton-jersey"), progress=lambda m: print("  " + m, flush=True))
    out["thickness"] = thickness
    print(f"  radius {thickness['radius_m']['as_labelled'] * 1e6:.1f} -> {thickness['radius_m']['thicker'] * 1e6:.1f} µm "
          f"(x{thickness['radius_ratio']:.3f}), areal density {thickness['areal_density_kg_m2']['as_labelled'] * 1e3:.0f} -> "
          f"{thickness['areal_density_kg_m2']['thicker'] * 1e3:.0f} g/m²; thicker higher everywhere: "
          f"{thickness['thicker_is_stronger']}")
    for direction, curves in thickness["directions"].items():
        for label, curve in curves.items():
            values = ", ".join(f"{f:.4g}" for f in curve["force_per_width_n_per_m"])
            print(f"  {direction:4s} {label:11s} N/m at strain {', '.join(f'{e:.3g}' for e in curve['strain'])}: {values}")

    print("(c) cotton-jersey's pattern in three fibres, sphere drape (quick mesh)")
    fibres = compare_fibre_drapes(Fabric.preset("cotton-jersey"), progress=lambda m: print("  " + m, flush=True))
    out["fibre_drapes"] = fibres
    for fibre, figures in fibres["fibres"].items():
        print(f"  {fibre:9s} drape coefficient {figures['drape_coefficient']:.3f}, lowest point "
              f"{figures['lowest_point_m'] * 100:.2f} cm, folds {figures['fold_count']}, "
              f"asymmetry {figures['weft_warp_asymmetry']:+.3f}")
    for pair, distance in fibres["rms_distance_m"].items():
        print(f"  RMS distance {pair}: {distance * 1e3:.1f} mm (threshold {fibres['difference_threshold_m'] * 1e3:g} mm)")
    print(f"  differ: {fibres['differ']}")

    path = Path(args.logs) / "paper_checks.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {path} in {time.perf_counter() - start:.0f} s")
    wovens = [p for p in PRESETS if named_patterns()[PRESETS[p].pattern] == "woven"]
    ok = all(out["bias_softness"][p]["bias_softer"] for p in wovens) \
        and thickness["thicker_is_stronger"] and fibres["differ"]
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

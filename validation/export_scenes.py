"""Every preset fabric in every exported MuJoCo scene, stepped and checked for stability:

    python validation/export_scenes.py                      # fit what is missing, 2 s per scene
    python validation/export_scenes.py --materials DIR      # material files <preset>.json from DIR
    python validation/export_scenes.py --seconds 0.5 --resolution 20 --fallback

Material files are cached in ``--materials`` (default ``<tmp>/yarnfit-materials``, outside the
repository): a preset whose file is missing there is fitted (``yarnfit.fabric_fit.fit_fabric``, 5–50 s
each) and written. Scenes go to ``<materials>/scenes/``. Prints one row per preset and scene
(steps, ms/step, bad-QACC warnings, largest vertex speed) and exits with status 1 if any scene
became unstable.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from yarnfit.fabric import PRESETS, Fabric
from yarnfit.fabric_fit import fit_fabric
from yarnfit.mujoco import DEFAULT_INTEGRATOR, DEFAULT_TIMESTEP, INTEGRATORS, SCENES
from yarnfit.mujoco.run import run_scene
from yarnfit.mujoco.scenes import ClothMaterial, export_options, export_scene


def material_file(preset: str, folder: Path) -> Path:
    """``folder/<preset>.json``, fitted and written first if it is not there."""
    path = folder / f"{preset}.json"
    if not path.exists():
        print(f"fitting {preset} (no {path})", file=sys.stderr, flush=True)
        fit_fabric(Fabric.preset(preset)).write(path)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--materials", type=Path, default=Path(tempfile.gettempdir()) / "yarnfit-materials",
                        help="folder of material files <preset>.json (missing ones are fitted and written there)")
    parser.add_argument("--presets", nargs="+", default=list(PRESETS), choices=list(PRESETS), metavar="PRESET")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES, metavar="SCENE")
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated time per scene (s)")
    parser.add_argument("--resolution", type=int, help="vertices per side (default: each scene's)")
    parser.add_argument("--timestep", type=float, default=DEFAULT_TIMESTEP)
    parser.add_argument("--integrator", default=DEFAULT_INTEGRATOR, choices=INTEGRATORS)
    parser.add_argument("--fallback", action="store_true", help="also run the plugin-free fallback scenes")
    args = parser.parse_args(argv)

    scenes_folder = args.materials / "scenes"
    variants = [False, True] if args.fallback else [False]
    header = (f"{'preset':<17} {'scene':<8} {'variant':<9} {'steps':>6} {'ms/step':>8} {'bad QACC':>8} "
              f"{'max |v| m/s':>11}  result")
    print(f"{args.integrator}, Δt = {args.timestep:g} s, {args.seconds:g} s simulated per scene")
    print(header)
    print("-" * len(header))
    unstable = 0
    for preset in args.presets:
        material = ClothMaterial.from_file(material_file(preset, args.materials))
        for scene in args.scenes:
            for fallback in variants:
                variant = "fallback" if fallback else "split"
                path = scenes_folder / f"{preset}-{scene}{'-fallback' if fallback else ''}.xml"
                # As `yarnfit export` writes the scene (its split and resolution unless given).
                export_scene(material, scene, path, **export_options(scene, resolution=args.resolution),
                             timestep=args.timestep, integrator=args.integrator, fallback=fallback)
                report = run_scene(path, args.seconds)
                unstable += not report.stable
                result = "stable" if report.stable else (
                    f"UNSTABLE at {report.simulated_s:.3g} s" + (" (non-finite)" if report.nonfinite else ""))
                print(f"{preset:<17} {scene:<8} {variant:<9} {report.steps:>6} {report.ms_per_step:>8.3g} "
                      f"{report.bad_qacc:>8} {report.max_speed:>11.3g}  {result}", flush=True)
    if unstable:
        print(f"{unstable} unstable scene{'s' if unstable > 1 else ''}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # fits run samples in worker processes
    sys.exit(main())

"""The validation suite (``yarnfit validate``, issue 6): a fitted material in FAB-style stretch
tests, against an explicit yarn-level swatch, in sphere and wall drapes and in garments on a moving
body, each scene recorded to ``logs/<material>/<scene>.rrd`` and summarised in ``summary.json``.

One module per scene; each exposes ``run_<scene>(material, *, quick=False, recording_path=None,
progress=None) -> dict`` whose keys carry their units (SI) and whose values are JSON numbers,
lists or dicts. This file imports nothing heavy: the command line builds its parser from it.
"""

SCENES = ("stretch", "yarn", "sphere", "wall", "body")
# The directions a strip is pulled in: the pull axis's angle from the weft, in degrees.
DIRECTIONS = {"weft": 0.0, "warp": 90.0, "bias": 45.0}

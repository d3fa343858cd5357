"""Loading the ``yarnfit.shell`` engine plugin into MuJoCo.

``import mujoco`` calls :func:`load` through the ``mujoco.plugins`` entry point, so a plain
``mujoco.MjModel.from_xml_path(scene)`` finds the plugin; calling it again is harmless. A C/C++
host loads the same file, :data:`LIBRARY`, with ``mj_loadPluginLibrary(path)`` before compiling.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

PLUGIN_NAME = "yarnfit.shell"
LIBRARY = Path(__file__).with_name("libyarnfit_shell.so")

_handle: ctypes.CDLL | None = None


def load() -> Path:
    """Load the plugin library once (its constructor registers ``yarnfit.shell``); returns its
    path. Raises ``FileNotFoundError`` if the package was installed without building it."""
    global _handle
    if _handle is None:
        if not LIBRARY.exists():
            raise FileNotFoundError(f"{LIBRARY} is missing: reinstall yarnfit with `pip install -e .`, "
                                    "which compiles the plugin")
        # Loaded like MuJoCo's bundled plugins (ctypes, not mj_loadPluginLibrary): this runs while
        # `mujoco` itself is still importing.
        _handle = ctypes.CDLL(str(LIBRARY))
    return LIBRARY

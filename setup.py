"""Build of the MuJoCo engine plugin ``yarnfit.shell`` (plugins/yarnfit_shell, C).

``pip install -e .`` (and any wheel build) compiles it against the headers and library of the
``mujoco-core`` wheel in the build environment (pinned in pyproject.toml to the runtime version:
the plugin ABI is MuJoCo's, version for version) into ``yarnfit/mujoco/libyarnfit_shell.so``. It
is a plain shared library, not a Python extension: ``yarnfit.mujoco.plugin.load`` hands it to
MuJoCo, and a C/C++ host loads it with ``mj_loadPluginLibrary``. At run time it binds to the
``libmujoco.so.4.0.0`` already loaded by the host (same soname); the rpath only helps a host
that loads it first.
"""

import os
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

PLUGIN_SOURCES = ["plugins/yarnfit_shell/yarnfit_shell.c"]
MUJOCO_LIBRARY = "libmujoco.so.4.0.0"


class BuildPlugin(build_ext):
    """Builds the plugin under its own name (``libyarnfit_shell.so``), without Python's
    extension suffix, with the mujoco package's include and library folders."""

    def build_extension(self, ext):
        import mujoco  # noqa: F401  (the build environment's mujoco-core: headers and libmujoco)

        folder = Path(mujoco.__file__).parent
        ext.include_dirs.append(str(folder / "include"))
        ext.library_dirs.append(str(folder))
        ext.extra_link_args += [f"-l:{MUJOCO_LIBRARY}", "-Wl,-rpath,$ORIGIN/../../mujoco", "-lm"]
        super().build_extension(ext)

    def get_ext_filename(self, fullname):
        # yarnfit.mujoco.libyarnfit_shell -> yarnfit/mujoco/libyarnfit_shell.so
        parts = fullname.split(".")
        return os.path.join(*parts[:-1], parts[-1] + ".so")

    def get_export_symbols(self, ext):
        return []  # no PyInit_ function: registration runs from the library's constructor


setup(
    ext_modules=[Extension("yarnfit.mujoco.libyarnfit_shell", sources=PLUGIN_SOURCES,
                           extra_compile_args=["-std=c11", "-O2", "-Wall", "-Wextra"])],
    cmdclass={"build_ext": BuildPlugin},
)

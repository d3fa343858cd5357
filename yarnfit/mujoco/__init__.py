"""MuJoCo side of yarnfit: the ``yarnfit.shell`` engine plugin (loaded by ``plugin.load``, which
``import mujoco`` calls through the ``mujoco.plugins`` entry point)."""

"""yarnfit: real fabric parameters for MuJoCo cloth, from a fabric's label.

Stages (one module each, data flowing one way): fibre and fabric data → periodic yarn patterns →
the yarn engine (:mod:`yarnfit.engine`) → homogenization → orthotropic StVK shell fit → MuJoCo
export → validation scenes. See ``README.md``.
"""

__version__ = "0.1.2"

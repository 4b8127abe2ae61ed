"""Learned force estimators (paper §IV-B): the ICFN, the RCFN and their files.

:class:`ICFN` maps one ICFN feature vector to the instantaneous contact force;
:class:`RCFN` maps the holding context to the relaxation parameters of Eq. 10,
which :func:`reconstruct` turns into the compensated force.  Both follow
scikit-learn's estimator conventions, predict with NumPy alone, and are saved
as arrays plus a JSON manifest by :func:`save_models` (no pickle).
"""

from relaxgrip.learning.icfn import ICFN, ICFN_CANDIDATES, select_icfn
from relaxgrip.learning.rcfn import RCFN, RCFN_ALPHAS, RCFN_TARGETS, reconstruct, select_rcfn
from relaxgrip.learning.store import ModelBundle, ModelFileError, load_models, save_models

__all__ = [
    "ICFN",
    "ICFN_CANDIDATES",
    "RCFN",
    "RCFN_ALPHAS",
    "RCFN_TARGETS",
    "ModelBundle",
    "ModelFileError",
    "load_models",
    "reconstruct",
    "save_models",
    "select_icfn",
    "select_rcfn",
]

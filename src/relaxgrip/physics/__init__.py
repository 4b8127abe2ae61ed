"""Pure physics of the gripper: functions of arrays, SI units, no I/O, no clock.

Randomness only ever enters through a :class:`numpy.random.Generator` passed
in by the caller.
"""

from relaxgrip.physics.beam import FingerParams
from relaxgrip.physics.contact import AdhesionParams
from relaxgrip.physics.smp import SMPParams
from relaxgrip.physics.thermal import HeatParams
from relaxgrip.physics.viscoelastic import PronySeries

__all__ = ["AdhesionParams", "FingerParams", "HeatParams", "PronySeries", "SMPParams"]

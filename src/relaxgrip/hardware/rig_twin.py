"""The twin of a rig: one :class:`~relaxgrip.twin.TwinConfig` built from a rig file.

Everything that belongs to the gripper comes from the rig file: the cameras,
marker and finger outline (:attr:`RigFile.geometry`), the finger's stiffness
and SMP, its heat model and heaters, the motor, the force reference's rate
and noise, the calibration object and where objects are usually held.  What
only a twin has (sensor noise and rendering, the unit-to-unit scatter, the
adhesion pads' physics, the integrator's steps, the object and scene of an
experiment) comes from ``base``, the twin's own by default.  The twin of
``docs/rigs/relaxgrip.toml`` is ``TwinConfig()``, bit for bit.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from relaxgrip.errors import InputError
from relaxgrip.hardware.rig_file import RigFile, load_rig
from relaxgrip.twin import TwinConfig

__all__ = ["load_twin_config", "twin_config_for_rig"]


def twin_config_for_rig(rig: RigFile, base: TwinConfig | None = None) -> TwinConfig:
    """The twin of ``rig``: its gripper, with ``base``'s twin-only settings.

    Parameters
    ----------
    rig : RigFile
        A validated rig file.
    base : TwinConfig, optional
        Where the twin-only settings come from (default: ``TwinConfig()``);
        its gripper properties are replaced by the rig's.  A base without a
        force sensor stays without one.

    Returns
    -------
    TwinConfig

    Raises
    ------
    InputError
        The rig's RGB camera has distortion coefficients: the twin renders a
        pinhole camera (``[rgb] dist = []`` for its twin).
    """
    cfg = base if base is not None else TwinConfig()
    if cfg.rgb is not None and rig.rgb.mount.intrinsics.dist:
        raise InputError(f"{rig.path}: [rgb] dist: the twin renders an undistorted pinhole "
                         "camera; its twin needs dist = [] (undistort the frames, or leave "
                         "the twin out of this rig)")
    sensor = None if cfg.force_sensor is None else rig.force_ref.sensor
    return replace(cfg, finger=rig.stiffness, heat=rig.heat, relax=rig.relax, motor=rig.motor,
                   rig=rig.geometry, contact_position_m=rig.finger.contact_m,
                   force_sensor=sensor, force_ball=rig.force_ball)


def load_twin_config(path: str | Path | None, base: TwinConfig | None = None) -> TwinConfig:
    """The twin of the rig file at ``path``; ``None``: ``base`` (our gripper by default).

    Raises
    ------
    InputError
        The rig file is unreadable or has a bad field (one line naming it).
    """
    if path is None:
        return base if base is not None else TwinConfig()
    return twin_config_for_rig(load_rig(path), base)

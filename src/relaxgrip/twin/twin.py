"""The digital twin of the two-finger SMP gripper.

A thin stateful shell around :mod:`relaxgrip.physics`: it holds the motor,
the two fingers' temperature fields and Maxwell branch forces, and the
object, and advances them with the exact integrators of the physics layer.
It implements :class:`relaxgrip.backend.Gripper` on an injected clock: each
``observe``/``act`` first integrates the physics up to ``clock.now()``, so the
same code runs in virtual time (as fast as the CPU allows) or in wall-clock
time.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import BackendInfo, Command, Observation, Truth
from relaxgrip.clock import TIME_SLACK_S, Clock, VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.physics.beam import (
    FingerParams,
    beam_grid,
    bending_stiffness_n_m2,
    smp_share,
    unit_profile_m_per_n,
)
from relaxgrip.physics.contact import adhesion_pulloff_n, friction_capacity_n, series_contact
from relaxgrip.physics.smp import branch_shares, relaxation_fraction, shift_factor
from relaxgrip.physics.thermal import (
    discrete_heat_system,
    duty_for_mean_temp,
    node_positions_m,
    steady_state_c,
)
from relaxgrip.physics.viscoelastic import phi1
from relaxgrip.twin.config import TWIN_VERSION, TwinConfig
from relaxgrip.twin.objects import ObjectSpec
from relaxgrip.twin.sensor_suite import SceneState, SensorSuite
from relaxgrip.twin.sensors import SceneObject

FloatArray = NDArray[np.float64]

__all__ = ["GripperTwin", "TwinMaterial"]

#: A temperature change (K) that triggers a new stiffness evaluation.
_REFRESH_K = 0.02
#: Plastic set (m) from which an object counts as visibly crushed.
_CRUSHED_M = 0.001
#: Steps whose lengths differ by less than this share their discretisation (relative).
_SAME_STEP_REL = 1e-9


#: Stream of the unit's random draws (apart from every run's).
_UNIT_STREAM = 0x756E6974


@dataclass(frozen=True)
class TwinMaterial:
    """Per-run draw of the twin's scatter (what one seed fixes, on its unit).

    Attributes
    ----------
    finger : tuple of FingerParams
        Each finger's beam (with the batch's Tg).
    stiffness_scale, relax_scale, tau_scale : tuple of float
        Per-finger factors on instantaneous stiffness, relaxing share and
        relaxation times.
    relax_scale_rubbery : tuple of float
        Per-finger factor on the extra relaxing share above the onset.
    contact_position_m : float
        Where the object touches the fingers in this run (m).
    ambient_c : float
        Ambient temperature of this run (°C).
    """

    finger: tuple[FingerParams, FingerParams]
    stiffness_scale: tuple[float, float]
    relax_scale: tuple[float, float]
    relax_scale_rubbery: tuple[float, float]
    tau_scale: tuple[float, float]
    contact_position_m: float
    ambient_c: float

    @classmethod
    def draw(cls, config: TwinConfig, rng: np.random.Generator) -> TwinMaterial:
        """Draw one run's scatter from ``rng`` (the unit's calibration from ``config.unit``)."""
        sc = config.scatter
        smp = config.finger.smp
        unit_rng = np.random.default_rng([config.unit, _UNIT_STREAM])
        tg_c = smp.tg_c + sc.tg_k * unit_rng.standard_normal()
        batch = replace(config.finger, smp=replace(smp, tg_c=tg_c))
        stiffness = np.exp(sc.stiffness_rel * unit_rng.standard_normal(2))

        def pair(sigma: float) -> tuple[float, float]:
            a, b = np.exp(sigma * rng.standard_normal(2))
            return float(a), float(b)

        contact = config.contact_position_m + sc.contact_position_m * rng.standard_normal()
        contact = float(np.clip(contact, 0.2 * config.finger.length_m, config.finger.length_m))
        return cls(
            finger=(batch, batch),
            stiffness_scale=(float(stiffness[0]), float(stiffness[1])),
            relax_scale=pair(sc.relax_fraction_rel),
            relax_scale_rubbery=pair(sc.relax_fraction_rel_rubbery),
            tau_scale=pair(sc.tau_rel),
            contact_position_m=contact,
            ambient_c=config.ambient_c + sc.ambient_k * rng.standard_normal(),
        )

    def scatter(self) -> dict[str, float]:
        """This run's draw, flat: each factor per finger (``_0``, ``_1``), contact, ambient."""
        out: dict[str, float] = {}
        for name in ("relax_scale", "relax_scale_rubbery", "tau_scale"):
            for j, value in enumerate(getattr(self, name)):
                out[f"{name}_{j}"] = value
        out["contact_position_m"] = self.contact_position_m
        out["ambient_c"] = self.ambient_c
        return out


def _check_seed(seed: object) -> int:
    """The seed as an ``int``; anything but a non-negative integer raises InputError."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


class _FingerStiffness:
    """A finger's temperature-dependent contact parameters at one temperature field."""

    __slots__ = ("_coeffs", "bend_ratio", "contact_slope_ratio", "k_e", "k_i", "marker_ratio",
                 "slope_ratio", "tau", "temp_eff_c", "temps_c")

    def __init__(self, temps_c: FloatArray, finger: FingerParams, nodes_m: FloatArray,
                 contact_m: float, marker_m: float, config: TwinConfig, stiffness_scale: float,
                 relax_scale: float, relax_scale_rubbery: float, tau_scale: float) -> None:
        x = beam_grid(finger)
        field_c = np.interp(x, nodes_m, temps_c)
        z, slope = unit_profile_m_per_n(contact_m, field_c, finger)
        c_a = float(np.interp(contact_m, x, z))
        # The branches feel the temperature where the finger bends: weight the
        # field by each section's share of the contact compliance.
        weight = np.clip(contact_m - x, 0.0, None) ** 2 / bending_stiffness_n_m2(field_c, finger)
        temp_eff = float(np.sum(weight * field_c) / np.sum(weight))
        smp = finger.smp
        k_inst = stiffness_scale / c_a
        if smp.material is not None:
            # A measured material (docs/material.md): each Prony term's share of the SMP's
            # loaded modulus, times the SMP's share of the contact compliance's stiffness
            # (d ln C / d ln E_smp, weighted as temp_eff is).
            s_share = float(np.sum(weight * smp_share(field_c, finger)) / np.sum(weight))
            shares = branch_shares(temp_eff, smp) * s_share * relax_scale
            total = float(shares.sum())
            if total > 0.95:
                shares = shares * (0.95 / total)
            self.k_e = k_inst * (1.0 - float(shares.sum()))
            self.k_i = k_inst * shares
        else:
            g_lo = smp.relax_fraction_glassy * relax_scale
            g_extra = (float(relaxation_fraction(temp_eff, smp)) - smp.relax_fraction_glassy)
            g = min(0.95, g_lo + g_extra * relax_scale * relax_scale_rubbery)
            w = np.asarray(config.relax.branch_weights)
            self.k_e = k_inst * (1.0 - g)
            self.k_i = k_inst * g * w
        a_t = float(shift_factor(temp_eff, smp))
        self.tau = np.asarray(config.relax.tau_ref_s) * a_t * tau_scale
        self._coeffs: tuple[float, tuple[float, ...], tuple[float, ...], float] | None = None
        #: The deflection along the finger (on :func:`beam_grid`) per unit at the contact.
        self.bend_ratio = z / c_a
        self.marker_ratio = float(np.interp(marker_m, x, z)) / c_a
        self.slope_ratio = float(np.interp(marker_m, x, slope)) / c_a
        self.contact_slope_ratio = float(np.interp(contact_m, x, slope)) / c_a
        self.temp_eff_c = temp_eff
        self.temps_c = temps_c.copy()

    def step_coefficients(self, dt_s: float) -> tuple[tuple[float, ...], tuple[float, ...], float]:
        """Branch decays ``e^{-dt/tau_i}``, gains ``k_i phi1(dt/tau_i)`` and the gains' sum."""
        # Steps of the same length up to round-off share their coefficients (times
        # hundreds of seconds into a run carry ~1e-11 of a 33 ms step in round-off).
        if self._coeffs is None or abs(self._coeffs[0] - dt_s) > _SAME_STEP_REL * dt_s:
            h = dt_s / self.tau
            gain = self.k_i * phi1(h)
            decay = tuple(np.exp(-h).tolist())
            self._coeffs = (dt_s, decay, tuple(gain.tolist()), float(gain.sum()))
        return self._coeffs[1], self._coeffs[2], self._coeffs[3]


class GripperTwin:
    """Seeded, stepped digital twin of the two-finger gripper.

    Parameters
    ----------
    config : TwinConfig
        Physics, geometry and scatter.
    seed : int
        Seed of the run-to-run scatter; the same seed gives the same run, bit
        for bit.
    clock : Clock, optional
        Time source; a fresh :class:`~relaxgrip.clock.VirtualClock` by default.
    """

    def __init__(self, config: TwinConfig | None = None, seed: int = 0,
                 clock: Clock | None = None) -> None:
        self.config = config if config is not None else TwinConfig()
        self.clock: Clock = clock if clock is not None else VirtualClock()
        self._nodes_m = node_positions_m(self.config.heat)
        self.reset(_check_seed(seed))

    # -- Gripper protocol -------------------------------------------------
    @property
    def info(self) -> BackendInfo:
        """Name and version of this backend."""
        return BackendInfo(name="twin", version=TWIN_VERSION, has_truth=True)

    def reset(self, seed: int | None = None) -> Observation:
        """Draw a new run (``seed`` or the previous one) and return to the open state."""
        if seed is not None:
            self.seed = _check_seed(seed)
        cfg = self.config
        self.material = TwinMaterial.draw(cfg, np.random.default_rng(self.seed))
        self._t = self.clock.now()
        self._command = Command()
        self._motor_mm = 0.0
        self._motor_v = 0.0
        self._arm_mm = 0.0
        self._forward_mm = 0.0
        self._object_x_mm = cfg.object_distance_m * 1e3
        self._object: ObjectSpec | None = cfg.object
        self._object_height_mm = 0.0
        self._grip_mm = 0.0  # arm height less the held object's: where the fingers hold it
        self._engaged = self._object is not None and cfg.object_distance_m == 0.0
        self._plastic_m = 0.0
        self._slipping = False
        self._force_n = 0.0
        self._external_n = 0.0
        self._scene_objects = cfg.scene
        ambient = self.material.ambient_c
        if cfg.initial_temp_c is None:
            start = np.full(cfg.heat.n_nodes, ambient)
        else:
            duty = duty_for_mean_temp(cfg.initial_temp_c, cfg.heat, ambient)
            start = steady_state_c(duty, cfg.heat, ambient)
            start += cfg.initial_temp_c - float(np.mean(start))
        self._set_temps(np.vstack([start, start]))
        self._x = [0.0, 0.0]
        n_branches = len(cfg.relax.tau_ref_s)
        self._branches = [[0.0] * n_branches, [0.0] * n_branches]
        self._stiff = [self._evaluate(0), self._evaluate(1)]
        self._stiff_temps = self._temps.copy()
        self._step_cache: tuple[float, FloatArray, FloatArray] | None = None
        self._heat_dt = 0.0
        self._heat_duty = [0.0, 0.0]
        self._motor_decay = (0.0, 1.0)
        self._stiffening_per_m2 = cfg.finger.stiffening / cfg.finger.length_m**2
        self._sensors = SensorSuite(cfg, self.seed, self._t, self._nodes_m)
        self._advance_to(self._t)  # the cameras' first frames
        return self.observe()

    def observe(self) -> Observation:
        """Integrate to the clock's time and report the state."""
        self._advance_to(self.clock.now())
        res = self.config.motor.encoder_resolution_mm
        return Observation(
            t_s=self._t,
            motor_position_mm=round(self._motor_mm / res) * res,
            arm_height_mm=self._arm_mm,
            heater_duty=self._command.heater_duty,
            arm_forward_mm=self._forward_mm,
            rgb=self._sensors.rgb_frame(),
            ir=self._sensors.ir_frame(),
            force_ref=self._sensors.take_force(),
            truth=self.truth(),
        )

    def act(self, command: Command) -> None:
        """Integrate to the clock's time under the old command, then latch ``command``."""
        self._advance_to(self.clock.now())
        self._command = command

    def close(self) -> None:
        """Stop the motor and switch the heaters off."""
        self._advance_to(self.clock.now())
        self._command = Command()

    # -- state ------------------------------------------------------------
    @property
    def time_s(self) -> float:
        """Time up to which the physics has been integrated (s)."""
        return self._t

    @property
    def contact_force_n(self) -> float:
        """Current true contact force (N)."""
        return self._force_n

    @property
    def motor_position_mm(self) -> float:
        """Closing motor's position, exact (mm from fully open; observations read it
        through the encoder's quantum)."""
        return self._motor_mm

    @property
    def aperture_m(self) -> float:
        """Distance between the undeflected finger contact faces (m)."""
        return self.config.rig.aperture_m(self._motor_mm)

    @property
    def object_ahead_m(self) -> float:
        """How far ahead of its grasp position the object stands (m); 0 between the fingers."""
        return (self._object_x_mm - self._forward_mm) * 1e-3

    def set_object(self, name: str | None, ahead_m: float = 0.0) -> None:
        """Place another catalogue object between the (open) fingers, or ahead of them.

        Parameters
        ----------
        name : str or None
            Catalogue key; ``None`` removes the object.
        ahead_m : float
            How far beyond the grasp position it stands on the table (m), at
            the arm's current height; 0 puts it between the fingers.
        """
        if not (math.isfinite(ahead_m) and ahead_m >= 0.0):
            raise InputError(f"object distance must be >= 0 m, got {ahead_m}")
        obj = None if name is None else self.config.object_spec(name)
        if obj is not None and ahead_m == 0.0 and self.aperture_m < obj.width_m:
            raise InputError(f"{name} is {obj.width_m * 1e3:g} mm wide and the fingers "
                             f"{self.aperture_m * 1e3:.1f} mm apart: open them first")
        self._object = obj
        self._engaged = self._object is not None and ahead_m == 0.0
        self._object_height_mm = self._arm_mm
        self._grip_mm = 0.0
        self._object_x_mm = self._forward_mm + ahead_m * 1e3
        self._plastic_m = 0.0
        self._external_n = 0.0

    def set_object_mass(self, mass_kg: float) -> None:
        """Change the mass of the current object from now on (water poured out of a cup)."""
        if self._object is None:
            raise InputError("there is no object whose mass could change")
        if not (math.isfinite(mass_kg) and mass_kg > 0.0):
            raise InputError(f"object mass must be > 0 kg, got {mass_kg}")
        self._object = replace(self._object, mass_kg=float(mass_kg))

    def set_external_force(self, force_n: float) -> None:
        """Push the held object towards finger 1 with ``force_n`` (a hand taking it), from now on.

        While the grip is closed the push shifts load from finger 0 (which
        carries the marker) to finger 1: finger 0 presses with the squeeze
        ``F`` (the truth's contact force), finger 1 with ``F + force_n``.  A
        negative ``force_n`` pushes towards finger 0 instead.  Once the grip
        opens at either finger, the hand carries the object and the fingers
        are free.  0 (the default) is no push.
        """
        if not math.isfinite(force_n):
            raise InputError(f"external force must be finite, got {force_n}")
        self._external_n = float(force_n)

    def set_scene(self, scene: tuple[SceneObject, ...]) -> None:
        """Replace the objects standing in view (the config's ``scene``) from now on."""
        scene = tuple(scene)
        for item in scene:
            if not isinstance(item, SceneObject):
                raise InputError(f"a scene holds SceneObject items, got {item!r}")
        self._scene_objects = scene

    def truth(self) -> Truth:
        """Ground truth at the integrated time."""
        s = self._stiff
        obj = self._object
        return Truth(
            contact_force_n=self._force_n,
            finger_deflection_m=(self._x[0], self._x[1]),
            marker_deflection_m=(self._x[0] * s[0].marker_ratio, self._x[1] * s[1].marker_ratio),
            marker_slope_rad=(math.atan(self._x[0] * s[0].slope_ratio),
                              math.atan(self._x[1] * s[1].slope_ratio)),
            contact_position_m=self.material.contact_position_m,
            finger_temps_c=self._temps_tuple,
            finger_effective_temp_c=(s[0].temp_eff_c, s[1].temp_eff_c),
            aperture_m=self.aperture_m,
            object_name=None if obj is None else obj.name,
            object_ahead_m=self.object_ahead_m,
            object_lifted=self._engaged and self._object_height_mm > 0.0,
            object_slipping=self._slipping,
            object_crushed=self._plastic_m > _CRUSHED_M,
            object_plastic_m=self._plastic_m,
        )

    # -- integration --------------------------------------------------------
    def _evaluate(self, j: int) -> _FingerStiffness:
        m = self.material
        return _FingerStiffness(
            self._temps[j], m.finger[j], self._nodes_m, m.contact_position_m,
            self.config.rig.marker.position_m, self.config, m.stiffness_scale[j],
            m.relax_scale[j], m.relax_scale_rubbery[j], m.tau_scale[j],
        )

    def _advance_to(self, t_s: float) -> None:
        """Integrate to ``t_s``, stopping at every camera capture on the way."""
        while True:
            t_capture = self._sensors.next_capture_s()
            if t_capture > t_s + TIME_SLACK_S:
                break
            # A capture that falls on the requested time up to round-off is taken there:
            # no sliver of a step between them.
            self._integrate_to(t_s if t_capture > t_s - TIME_SLACK_S else t_capture)
            # A capture that a later one of this advance replaces is never seen: its
            # scene is not assembled.
            self._sensors.capture(t_capture, self._scene, until_s=t_s)
        self._integrate_to(t_s)

    def _integrate_to(self, t_s: float) -> None:
        remaining = t_s - self._t
        if remaining <= 0.0:
            return
        n = max(1, math.ceil(remaining / self.config.max_step_s - 1e-9))
        dt = remaining / n
        obj = self._object
        sensors = self._sensors
        sensing = (obj is not None and obj.force_sensor and self._engaged
                   and sensors.force_sensor is not None)
        if sensing:
            sensors.record_force(self._t, self._force_n)
        for _ in range(n):
            self._step(dt)
            self._t += dt
            if sensing:
                sensors.record_force(self._t, self._force_n)
        if not sensing:
            sensors.skip_force(t_s)
        self._t = t_s

    def _scene(self) -> SceneState:
        """What the cameras see now."""
        cfg = self.config
        j = cfg.rig.marker_finger
        stiff = self._stiff[j]
        fwd_m, arm_m = self._forward_mm * 1e-3, self._arm_mm * 1e-3
        objects = [
            (cfg.object_spec(o.name), (o.position_m[0] - fwd_m, o.position_m[1],
                                       o.position_m[2] - arm_m))
            for o in self._scene_objects
        ]
        if self._object is not None:
            centre = (self.material.contact_position_m + self.object_ahead_m, 0.0,
                      (self._object_height_mm - self._arm_mm) * 1e-3)
            objects.append((self._object, centre))
        bend = None
        if cfg.ir is not None and cfg.ir.draw_bend:
            bend = (beam_grid(cfg.finger), np.stack([self._x[k] * self._stiff[k].bend_ratio
                                                     for k in (0, 1)]))
        return SceneState(
            marker_deflection_m=self._x[j] * stiff.marker_ratio,
            marker_slope_rad=math.atan(self._x[j] * stiff.slope_ratio),
            aperture_m=self.aperture_m,
            finger_temps_c=self._temps.copy(),
            ambient_c=self.material.ambient_c,
            objects=tuple(objects),
            finger_bend_m=bend,
        )

    def _step(self, dt: float) -> None:
        cfg = self.config
        cmd = self._command
        # Motor: first-order velocity lag, integrated exactly over the step.
        mp = cfg.motor
        v_cmd = min(max(cmd.motor_velocity_mm_s, -mp.max_velocity_mm_s), mp.max_velocity_mm_s)
        if self._motor_decay[0] != dt:
            self._motor_decay = (dt, math.exp(-dt / mp.lag_s))
        e = self._motor_decay[1]
        pos = self._motor_mm + v_cmd * dt + (self._motor_v - v_cmd) * mp.lag_s * (1.0 - e)
        self._motor_v = v_cmd + (self._motor_v - v_cmd) * e
        if not 0.0 <= pos <= mp.stroke_mm:
            pos = min(max(pos, 0.0), mp.stroke_mm)
            self._motor_v = 0.0
        self._motor_mm = pos
        if cmd.arm_velocity_mm_s != 0.0:
            self._raise_arm(cmd.arm_velocity_mm_s * dt)
        if cmd.approach_velocity_mm_s != 0.0:
            self._approach(cmd.approach_velocity_mm_s * dt)

        # Heat: the film sees the PWM's mean power, and the finger's thermal
        # time constants are seconds, so the heat model advances in steps of
        # ``thermal_step_s`` under the mean duty of that interval.
        self._heat_dt += dt
        self._heat_duty[0] += cmd.heater_duty[0] * dt
        self._heat_duty[1] += cmd.heater_duty[1] * dt
        if self._heat_dt >= cfg.thermal_step_s - 1e-12:
            self._advance_heat()

        # Fingers: exact Maxwell update (Eq. 2) made implicit in the new
        # deflection, F_j = K_j X_j + c_j, then the series contact solve.
        # Plain floats: two fingers of a few branches, where NumPy calls cost more.
        inv_len2 = self._stiffening_per_m2
        k_eff: list[float] = []
        offset: list[float] = []
        coeffs = []
        for j in range(2):
            decay, gain, gain_sum = self._stiff[j].step_coefficients(dt)
            x = self._x[j]
            stiffen = 1.0 + inv_len2 * x * x
            memory = sum(map(operator.mul, self._branches[j], decay))
            k_eff.append(stiffen * (self._stiff[j].k_e + gain_sum))
            offset.append(stiffen * (memory - gain_sum * x))
            coeffs.append((decay, gain))
        rigid = cfg.rigid_finger
        if rigid is not None:
            # A rigid jaw in place of that finger: infinitely stiff, it never bends.
            k_eff[rigid], offset[rigid] = math.inf, 0.0

        obj = self._object
        if obj is not None and self._engaged:
            delta = obj.width_m - self._plastic_m - self.aperture_m
            # A hand's push: F_1 = F_0 + push.  The chain carries the smaller of the two
            # forces, so that neither contact pulls: F_0 with finger 1's offset lowered by
            # the push, or (a push towards finger 0) F_1 with finger 0's offset raised by it.
            push = self._external_n
            if push == 0.0:
                loaded = offset
            elif push > 0.0:
                loaded = [offset[0], offset[1] - push]
            else:
                loaded = [offset[0] + push, offset[1]]
            sol = series_contact(delta, k_eff, loaded, obj.stiffness_n_per_m, obj.yield_force_n)
            self._plastic_m += sol.plastic_m
            x_new = sol.finger_deflection_m
            force = sol.force_n
            if push != 0.0 and force == 0.0:  # off a finger: the hand has it, both fingers free
                x_new = (-offset[0] / k_eff[0], -offset[1] / k_eff[1])
            elif push < 0.0:
                force -= push  # the chain's force is finger 1's: F_0 = F_1 - push
        else:
            x_new = (-offset[0] / k_eff[0], -offset[1] / k_eff[1])
            force = 0.0
        for j in range(2):
            decay, gain = coeffs[j]
            dx = x_new[j] - self._x[j]
            self._branches[j] = [f * d + g * dx
                                 for f, d, g in zip(self._branches[j], decay, gain, strict=True)]
        self._x = [x_new[0], x_new[1]]
        self._force_n = force
        if obj is not None and self._engaged:
            self._lift(obj, force)

    def _set_temps(self, temps_c: FloatArray) -> None:
        self._temps = temps_c
        self._temps_tuple = (tuple(temps_c[0].tolist()), tuple(temps_c[1].tolist()))

    def _advance_heat(self) -> None:
        dt = self._heat_dt
        if dt <= 0.0:
            return
        # Heat steps of the same length up to round-off share their discretisation.
        if self._step_cache is None or abs(self._step_cache[0] - dt) > _SAME_STEP_REL * dt:
            ad, bd = discrete_heat_system(self.config.heat, dt)
            self._step_cache = (dt, ad.T.copy(), bd.T.copy())
        _, ad_t, bd_t = self._step_cache
        ambient = self.material.ambient_c
        inputs = np.array([[self._heat_duty[0] / dt, ambient], [self._heat_duty[1] / dt, ambient]])
        self._set_temps(self._temps @ ad_t + inputs @ bd_t)
        self._heat_dt = 0.0
        self._heat_duty = [0.0, 0.0]
        if np.abs(self._temps - self._stiff_temps).max() > _REFRESH_K:
            self._stiff = [self._evaluate(0), self._evaluate(1)]
            self._stiff_temps = self._temps.copy()

    def _raise_arm(self, step_mm: float) -> None:
        """Move the arm up (or down, to the table at most).

        Coming down onto an object that stands at the grasp position without
        being held (one that slid out of the fingers), the fingers reach down
        beside it if they are open wide enough, and stop on its top if not.
        """
        arm = max(0.0, self._arm_mm + step_mm)
        obj = self._object
        top_mm = math.inf if obj is None else self._object_height_mm + obj.grip_length_m * 1e3
        passing = self._arm_mm >= top_mm > arm  # down past the object's top
        self._arm_mm = arm
        if obj is None or self._engaged or not (passing and self._at_grasp()):
            return
        if not self._engage(obj):  # too narrow to reach down beside it
            self._arm_mm = top_mm

    def _approach(self, step_mm: float) -> None:
        """Move the arm along the fingers.

        A lifted object travels with the gripper; one standing on the table
        stops the arm when it reaches the grasp position, and enters the grasp
        if the fingers are open wide enough; backing off leaves it behind.
        """
        obj = self._object
        if obj is None:
            self._forward_mm += step_mm
            return
        if self._engaged and self._object_height_mm > 0.0:
            self._forward_mm += step_mm
            self._object_x_mm += step_mm
            return
        self._forward_mm = min(self._forward_mm + step_mm, self._object_x_mm)
        if self._engaged:
            self._engaged = self._at_grasp()
            return
        level = abs(self._arm_mm - self._object_height_mm) * 1e-3 < obj.grip_length_m
        if self._at_grasp() and level:
            self._engage(obj)

    def _at_grasp(self) -> bool:
        """Whether the arm has come forward to the object's grasp position."""
        return self._forward_mm >= self._object_x_mm - 1e-9

    def _engage(self, obj: ObjectSpec) -> bool:
        """Take ``obj`` between the fingers, held at the arm's height, if they are open wide
        enough for it; whether they are."""
        if self.aperture_m < obj.width_m - self._plastic_m:
            return False
        self._engaged = True
        self._grip_mm = self._arm_mm - self._object_height_mm
        return True

    def _lift(self, obj: ObjectSpec, force_n: float) -> None:
        """Carry the object with the arm if friction and adhesion hold its weight.

        The fingers hold it where they took it (``_grip_mm`` below the arm):
        an object that slipped down the fingers to the table and is gripped
        again rises with the arm from there.  Let go of in the air (no
        squeeze, no hand holding it), it falls to the table.
        """
        base = self._arm_mm - self._grip_mm  # the held object's height
        let_go = force_n <= 0.0 and self._external_n == 0.0 and self._object_height_mm > 0.0
        if base <= self._object_height_mm and not let_go:
            if force_n > 0.0 and self._object_height_mm > 0.0:
                # Lowered while held: it goes down with the fingers, to the table at most.
                self._object_height_mm = max(base, 0.0)
            if base < self._object_height_mm:  # lowered along it where it stands
                self._grip_mm = self._arm_mm - self._object_height_mm
            self._slipping = False
            return
        s0, s1 = self._stiff
        tilt = 0.5 * (self._x[0] * s0.contact_slope_ratio + self._x[1] * s1.contact_slope_ratio)
        pad_c = float(np.mean(self._temps[:, -2:]))
        capacity = float(friction_capacity_n(force_n, obj.friction_coeff, tilt))
        capacity += float(adhesion_pulloff_n(pad_c, obj.surface == "flat", self.config.adhesion))
        if force_n > 0.0 and capacity >= obj.weight_n:
            self._object_height_mm = max(base, self._object_height_mm)
            self._slipping = False
            return
        self._slipping = True
        if self._object_height_mm > 0.0:
            self._object_height_mm = 0.0  # it falls back to the table
        self._grip_mm = self._arm_mm - self._object_height_mm  # the fingers slide along it
        if (self._arm_mm - self._object_height_mm) * 1e-3 > obj.grip_length_m:
            self._engaged = False  # the fingers have slid off it

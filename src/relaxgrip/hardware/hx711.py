"""The emulator's load cell: a strain-gauge bridge read by an HX711 24-bit ADC.

The calibration object's load cell is a full bridge of ``sensitivity_mv_per_v``
at ``capacity_n``, excited from the HX711's analogue supply, so its reading is
ratiometric: the counts per newton do not depend on the supply voltage,

    counts = offset + F · sensitivity · gain · 2^24 / capacity  (+ noise),

saturated to the signed 24-bit range.  The HX711 converts continuously at 10
or 80 samples per second (its RATE pin); each conversion is modelled as the
mean input over its period (the converter's digital filter, to first order),
and carries the datasheet's input-referred noise (50 nV rms at 10 SPS, 90 nV
at 80 SPS, gain 128).  The bridge's zero balance is drawn per unit from a
seeded generator: a host does not know it before a tare or a calibration.

:class:`Hx711Model` is fed the force on the cell as the emulator integrates
the twin and returns the conversions that completed; the Python MCU reports
them in Status, and the simulated firmware reads them from the HX711's pins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from relaxgrip.clock import TIME_SLACK_S
from relaxgrip.errors import InputError
from relaxgrip.validate import check_positive

__all__ = ["COUNTS_MAX", "COUNTS_MIN", "Hx711Config", "Hx711Model"]

COUNTS_MIN = -(1 << 23)
"""Most negative HX711 output (0x800000)."""
COUNTS_MAX = (1 << 23) - 1
"""Most positive HX711 output (0x7FFFFF)."""
_RATES_SPS = (10.0, 80.0)
#: Datasheet input-referred noise at gain 128 (V rms), by output rate.
_NOISE_V_RMS = {10.0: 50e-9, 80.0: 90e-9}


@dataclass(frozen=True)
class Hx711Config:
    """A load cell and its HX711 (channel A, gain 128).

    Attributes
    ----------
    rate_sps : float
        Output rate set by the RATE pin: 10 or 80 samples per second.
    capacity_n : float
        Rated load of the cell (N): a 2 kg bar cell by default.
    sensitivity_mv_per_v : float
        Rated output at capacity (mV per V of excitation).
    avdd_v : float
        HX711 analogue supply, which also excites the bridge (V); sets the
        noise in counts only (the reading is ratiometric).
    zero_balance_sd_mv_per_v : float
        Spread of the unloaded bridge's output between units (mV/V, 1 sd).
    gain : int
        Programmable gain of channel A (128).
    """

    rate_sps: float = 10.0
    capacity_n: float = 19.6
    sensitivity_mv_per_v: float = 1.0
    avdd_v: float = 4.23
    zero_balance_sd_mv_per_v: float = 0.05
    gain: int = 128

    def __post_init__(self) -> None:
        if self.rate_sps not in _RATES_SPS:
            raise InputError(f"HX711 rate_sps must be 10 or 80, got {self.rate_sps}")
        for name in ("capacity_n", "sensitivity_mv_per_v", "avdd_v"):
            check_positive(getattr(self, name), name)
        if not (math.isfinite(self.zero_balance_sd_mv_per_v)
                and self.zero_balance_sd_mv_per_v >= 0.0):
            raise InputError("zero_balance_sd_mv_per_v must be >= 0, got "
                             f"{self.zero_balance_sd_mv_per_v}")
        if self.gain != 128:
            raise InputError(f"the load cell is read on channel A at gain 128, got {self.gain}")

    @property
    def period_s(self) -> float:
        """Time between conversions (s)."""
        return 1.0 / self.rate_sps

    @property
    def counts_per_mv_per_v(self) -> float:
        """Counts per mV/V of bridge output: ``gain · 2^24 / 1000``."""
        return self.gain * float(1 << 24) / 1000.0

    @property
    def counts_per_n(self) -> float:
        """Nominal scale (counts per newton)."""
        return self.sensitivity_mv_per_v / self.capacity_n * self.counts_per_mv_per_v

    @property
    def noise_counts(self) -> float:
        """Conversion noise (counts rms) at the configured rate."""
        return _NOISE_V_RMS[self.rate_sps] * self.gain * float(1 << 24) / self.avdd_v


class Hx711Model:
    """Conversions of one HX711 unit, fed the force on its cell in time order.

    Parameters
    ----------
    config : Hx711Config
        The cell and converter.
    rng : numpy.random.Generator
        Draws the unit's zero balance, then each conversion's noise.
    start_s : float
        Power-up time (s); the first conversion completes one period later.

    Attributes
    ----------
    offset_counts : float
        The unloaded reading of this unit (counts), as a calibration would find it.
    """

    def __init__(self, config: Hx711Config, rng: np.random.Generator,
                 start_s: float = 0.0) -> None:
        self.config = config
        self._rng = rng
        self.offset_counts = float(rng.normal(0.0, config.zero_balance_sd_mv_per_v)
                                   * config.counts_per_mv_per_v)
        self._period_s = config.period_s
        self._k = 1  # index of the next conversion: it completes at start + k · period
        self._start_s = float(start_s)
        self._t_s = float(start_s)
        self._force_n = 0.0
        self._integral = 0.0  # ∫ F dt over the current conversion so far (N·s)

    @property
    def next_conversion_s(self) -> float:
        """Completion time of the next conversion (s)."""
        return self._start_s + self._k * self._period_s

    def _counts(self, mean_force_n: float) -> int:
        cfg = self.config
        value = (self.offset_counts + mean_force_n * cfg.counts_per_n
                 + cfg.noise_counts * float(self._rng.standard_normal()))
        return int(min(COUNTS_MAX, max(COUNTS_MIN, round(value))))

    def feed(self, t_s: float, force_n: float) -> list[tuple[float, int]]:
        """Advance to ``t_s``, the force on the cell going linearly to ``force_n`` there.

        Parameters
        ----------
        t_s : float
            Time of this reading (s), not before the previous one.
        force_n : float
            Force on the cell at ``t_s`` (N, compression positive).

        Returns
        -------
        list of (float, int)
            Completion time (s) and counts of every conversion that completed
            in ``(previous t, t_s]``, oldest first.
        """
        out: list[tuple[float, int]] = []
        t0, f0 = self._t_s, self._force_n
        if t_s <= t0:
            self._force_n = float(force_n)
            return out
        slope = (force_n - f0) / (t_s - t0)
        while self.next_conversion_s <= t_s + TIME_SLACK_S:  # k · period's round-off
            t_c = self.next_conversion_s
            f_c = f0 + slope * (t_c - t0)
            self._integral += 0.5 * (f0 + f_c) * (t_c - t0)
            out.append((t_c, self._counts(self._integral / self._period_s)))
            self._integral = 0.0
            self._k += 1
            t0, f0 = t_c, f_c
        self._integral += 0.5 * (f0 + force_n) * (t_s - t0)
        self._t_s, self._force_n = float(t_s), float(force_n)
        return out

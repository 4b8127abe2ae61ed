"""The emulator's HX711 load cell: scale, zero, noise, rate, filtering, saturation."""

from __future__ import annotations

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.hardware.hx711 import COUNTS_MAX, COUNTS_MIN, Hx711Config, Hx711Model


def test_scale_is_ratiometric_and_noise_follows_the_datasheet() -> None:
    cfg = Hx711Config()
    # 1 mV/V at 19.6 N, gain 128, 2^24 counts over ±0.5·AVDD/128: ~109,574 counts per newton.
    assert cfg.counts_per_n == pytest.approx(1e-3 * 128 * 2**24 / 19.6)
    assert cfg.counts_per_n == pytest.approx(Hx711Config(avdd_v=3.3).counts_per_n)
    assert cfg.noise_counts == pytest.approx(50e-9 * 128 * 2**24 / 4.23)
    assert Hx711Config(rate_sps=80.0).noise_counts > cfg.noise_counts


@pytest.mark.parametrize("rate_sps", [10.0, 80.0])
def test_conversions_come_at_the_rate_with_the_force_and_noise(rate_sps: float) -> None:
    cfg = Hx711Config(rate_sps=rate_sps)
    model = Hx711Model(cfg, np.random.default_rng(4), start_s=2.0)
    out = []
    for k in range(1, 1001):  # 10 s in 10 ms steps, 3 N on the cell
        out += model.feed(2.0 + 0.01 * k, 3.0)
    t = np.array([o[0] for o in out])
    counts = np.array([o[1] for o in out], dtype=float)
    assert len(out) == round(10 * rate_sps)
    np.testing.assert_allclose(np.diff(t), 1 / rate_sps, atol=1e-9)
    assert t[0] == pytest.approx(2.0 + 1 / rate_sps)
    force = (counts - model.offset_counts) / cfg.counts_per_n
    # The first conversion averages the step from 0 N up to 3 N over 10 ms.
    assert force[1:].mean() == pytest.approx(3.0, abs=3 * cfg.noise_counts / cfg.counts_per_n)
    assert (counts[1:] - counts[1:].mean()).std() == pytest.approx(cfg.noise_counts, rel=0.35)


def test_a_conversion_is_the_mean_force_over_its_period() -> None:
    cfg = Hx711Config(zero_balance_sd_mv_per_v=0.0)
    model = Hx711Model(cfg, np.random.default_rng(0))
    # A ramp 0 -> 10 N over the first conversion period, read at two odd times.
    assert model.feed(0.037, 3.7) == []
    ((t_c, counts),) = model.feed(0.1, 10.0)
    assert t_c == pytest.approx(0.1)
    assert counts / cfg.counts_per_n == pytest.approx(5.0, abs=1e-3)
    # A reading that spans two conversions splits the ramp between them.
    (first, second) = model.feed(0.3, 10.0)
    assert [first[0], second[0]] == pytest.approx([0.2, 0.3])
    assert first[1] / cfg.counts_per_n == pytest.approx(10.0, abs=1e-3)


def test_zero_balance_is_drawn_per_unit_and_the_output_saturates() -> None:
    offsets = {Hx711Model(Hx711Config(), np.random.default_rng(s)).offset_counts
               for s in range(5)}
    assert len(offsets) == 5
    model = Hx711Model(Hx711Config(), np.random.default_rng(1))
    model.feed(0.0, 500.0)  # a step at power-up: the force holds from now on
    ((_, high),) = model.feed(0.1, 500.0)
    model.feed(0.1, -500.0)
    ((_, low),) = model.feed(0.2, -500.0)
    assert high == COUNTS_MAX
    assert low == COUNTS_MIN


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"rate_sps": 20.0}, "rate_sps must be 10 or 80"),
    ({"capacity_n": 0.0}, "capacity_n"),
    ({"gain": 64}, "gain 128"),
    ({"zero_balance_sd_mv_per_v": -1.0}, "zero_balance_sd_mv_per_v must be >= 0"),
])
def test_bad_configs_are_refused(kwargs: dict[str, float], words: str) -> None:
    with pytest.raises(InputError, match=words):
        Hx711Config(**kwargs)  # type: ignore[arg-type]

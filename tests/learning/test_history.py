"""The loading history: retained shares, the unrelaxed ICFN's labels, storage, estimators."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from relaxgrip.control.estimators import (
    FixedEstimator,
    IcfnEstimator,
    RelaxEstimator,
    bundle_estimator,
    make_estimator,
)
from relaxgrip.errors import InputError
from relaxgrip.learning.history import (
    LoadingHistory,
    UnrelaxedIcfn,
    features_temp_c,
    retained_shares,
)
from relaxgrip.learning.icfn import ICFN
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.learning.rcfn import RCFN
from relaxgrip.learning.store import ModelFileError, load_models, save_models
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
from relaxgrip.twin.config import TWIN_VERSION

# The ensembles here train for a few dozen epochs on tiny data, to test the plumbing: that
# their optimiser has not converged is expected, not news.
pytestmark = pytest.mark.filterwarnings(
    "ignore:Stochastic Optimizer:sklearn.exceptions.ConvergenceWarning")

DX = ICFN_SCHEMA.index("marker_dx_m")
TEMPS = (ICFN_SCHEMA.index("f0_temp_mean_c"), ICFN_SCHEMA.index("f1_temp_mean_c"))


def _model() -> ObserverModel:
    arrays = {
        "temps_c_": np.array([30.0, 40.0, 50.0]),
        "tau_ref_s_": np.array([2.0, 20.0, 200.0]),
        "log_shift_": np.array([1.0, 0.0, -1.0]),
        "branch_share_": np.array([[0.08, 0.10, 0.15], [0.08, 0.10, 0.15], [0.10, 0.13, 0.20]]),
        "log_stiffness_": np.array([0.1, 0.0, -0.3]),
        "band_t_s_": np.array([10.0, 100.0]),
        "band_rel_": np.array([0.05, 0.08]),
        "onset_rel_": np.array([0.05]),
    }
    return ObserverModel.from_arrays(arrays, ObserverModel().get_params())


def _features(dx_m: float, temp_c: float = 40.0) -> np.ndarray:
    x = np.zeros(len(ICFN_SCHEMA))
    x[DX] = dx_m
    x[list(TEMPS)] = temp_c
    return x


def test_a_step_retains_everything_then_relaxes_as_the_prony_series() -> None:
    model = _model()
    h = LoadingHistory(model)
    h.advance(0.0, 1e-5, 40.0)  # below contact: nothing loads
    assert h.branches_m is None
    assert h.retained() == 1.0
    h.advance(1.0, 1e-3, 40.0)  # contact: the deflection arrived within the frame
    assert h.retained() == pytest.approx(1.0)
    for t in np.arange(1.0, 301.0, 1 / 30):
        h.advance(float(t), 1e-3, 40.0)
    k_e, k_i, tau = model.parameters(40.0)
    expected = (k_e + float(np.sum(k_i * np.exp(-(300.0 - 1.0) / tau)))) / (k_e + k_i.sum())
    assert h.retained() == pytest.approx(expected, rel=1e-3)
    assert h.relaxed_m() == pytest.approx(
        1e-3 * float(np.sum(k_i * -np.expm1(-(300.0 - 1.0) / tau))), rel=1e-3)
    h.reset()
    assert h.branches_m is None
    assert math.isnan(h.unit_force_m())


def test_warmed_at_a_fixed_deflection_a_finger_keeps_its_branch_forces() -> None:
    # Eq. 2 as the twin: the branches carry their forces over a change of k_i(T), while
    # the instantaneous stiffness falls, so the share passes 1 (documented).
    h = LoadingHistory(_model())
    h.advance(0.0, 1e-3, 30.0)
    assert h.branches_m is not None
    before = h.branches_m.copy()
    h.advance(1e-6, 1e-3, 55.0)
    after = h.branches_m
    assert after is not None
    np.testing.assert_allclose(after, before, rtol=1e-5)  # 1 µs of relaxation
    assert h.retained() > 1.0


@pytest.mark.parametrize("temp_c", [30.0, 45.0])
def test_a_slower_closing_retains_less_at_the_same_deflection(temp_c: float) -> None:
    def closing(speed_m_s: float) -> float:
        h = LoadingHistory(_model())
        for t in np.arange(0.0, 2e-3 / speed_m_s + 1e-9, 1 / 30):
            h.advance(float(t), speed_m_s * float(t), temp_c)
        return h.retained()

    fast, slow = closing(1e-3), closing(1e-4)
    assert 0.0 < slow < fast < 1.0


def _episode(episode: int, speed_m_s: float, temp_c: float, n: int = 12) -> pd.DataFrame:
    t = np.linspace(0.0, 3e-3 / speed_m_s, n)
    dx = np.maximum(speed_m_s * (t - t[1]), 0.0)  # two samples before contact
    rows = pd.DataFrame([_features(d, temp_c) for d in dx], columns=list(ICFN_SCHEMA.names))
    rows.insert(0, "t_s", t + 10.0 * episode)
    rows.insert(0, "episode", episode)
    return rows


def test_retained_shares_integrate_each_episode_from_its_contact() -> None:
    model = _model()
    rows = pd.concat([_episode(0, 1e-3, 40.0), _episode(1, 2e-4, 45.0)], ignore_index=True)
    shares = retained_shares(rows, model)
    assert shares[:2].tolist() == [1.0, 1.0]  # before contact
    for episode, speed, temp in ((0, 1e-3, 40.0), (1, 2e-4, 45.0)):
        ep = rows[rows["episode"] == episode]
        h = LoadingHistory(model)
        t0 = float(ep["t_s"].iloc[0])
        t_end = float(ep["t_s"].iloc[-1])
        for t in np.linspace(t0, t_end, 3001):
            h.advance(float(t), max(speed * (float(t) - float(ep["t_s"].iloc[1])), 0.0), temp)
        assert shares[ep.index[-1]] == pytest.approx(h.retained(), abs=2e-3)
    # Rows in another order give each row the same share.
    shuffled = rows.sample(frac=1.0, random_state=1)
    np.testing.assert_allclose(retained_shares(shuffled, model), shares[shuffled.index])
    assert features_temp_c(rows[list(ICFN_SCHEMA.names)].to_numpy())[-1] == 45.0


@pytest.fixture(scope="module")
def fitted() -> tuple[ICFN, ICFN, RCFN]:
    rng = np.random.default_rng(0)
    X = rng.normal(size=(200, len(ICFN_SCHEMA)))
    y = X[:, 0] + 0.3 * X[:, 3] ** 2
    icfn = ICFN(hidden_layer_sizes=(8,), learning_rate_init=1e-2, max_iter=200).fit(X, y)
    unrelaxed = ICFN(hidden_layer_sizes=(8,), learning_rate_init=1e-2, max_iter=200,
                     random_state=1).fit(X, 2.0 * y)
    Xr = rng.normal(size=(200, len(RCFN_SCHEMA)))
    rcfn = RCFN().fit(Xr, np.column_stack([0.2 + 0.01 * Xr[:, 0], 3.0 + 0.1 * Xr[:, 1]]))
    return icfn, unrelaxed, rcfn


def _save(directory: Path, fitted: tuple[ICFN, ICFN, RCFN], with_unrelaxed: bool = True) -> None:
    icfn, unrelaxed, rcfn = fitted
    save_models(directory, icfn, rcfn, icfn_feature_schema=ICFN_SCHEMA,
                rcfn_feature_schema=RCFN_SCHEMA, twin_version=TWIN_VERSION,
                training={"test": True},
                unrelaxed=UnrelaxedIcfn((unrelaxed, icfn), _model()) if with_unrelaxed else None)


def test_the_unrelaxed_icfn_and_its_branch_parameters_round_trip(
        tmp_path: Path, fitted: tuple[ICFN, ICFN, RCFN]) -> None:
    _save(tmp_path / "with", fitted)
    bundle = load_models(tmp_path / "with", icfn_feature_schema=ICFN_SCHEMA,
                         rcfn_feature_schema=RCFN_SCHEMA)
    assert bundle.unrelaxed is not None
    x = _features(1e-3)
    assert len(bundle.unrelaxed.members) == 2
    assert bundle.unrelaxed.predict_one(x) == pytest.approx(
        0.5 * (fitted[1].predict_one(x) + fitted[0].predict_one(x)))
    np.testing.assert_allclose(bundle.unrelaxed.predict(np.stack([x, 2 * x])),
                               [bundle.unrelaxed.predict_one(x),
                                bundle.unrelaxed.predict_one(2 * x)])
    for name, value in _model().to_arrays().items():
        np.testing.assert_array_equal(bundle.unrelaxed.model.to_arrays()[name], value)
    relax = bundle_estimator("relax", bundle)
    assert isinstance(relax, RelaxEstimator)
    assert relax.icfn.unrelaxed is bundle.unrelaxed
    _save(tmp_path / "without", fitted, with_unrelaxed=False)
    assert load_models(tmp_path / "without").unrelaxed is None
    assert not (tmp_path / "without" / "icfn_unrelaxed.npz").exists()


#: An ensemble on the pose and the warmest beams, as the shipped one reads.
_SUBSET = (*ICFN_SCHEMA.names[:9], "f0_temp_max_c", "f1_temp_max_c")


def _subset_pair() -> tuple[ICFN, ...]:
    rng = np.random.default_rng(2)
    X = rng.normal(size=(120, len(_SUBSET)))
    return tuple(ICFN(hidden_layer_sizes=(4,), learning_rate_init=1e-2, max_iter=100,
                      random_state=seed).fit(X, X[:, 0] + X[:, -1]) for seed in (0, 1))


def test_an_ensemble_on_some_features_reads_them_from_the_whole_vector(
        tmp_path: Path, fitted: tuple[ICFN, ICFN, RCFN]) -> None:
    icfn, _, rcfn = fitted
    members = _subset_pair()
    subset = UnrelaxedIcfn(members, _model(), _SUBSET)
    save_models(tmp_path, icfn, rcfn, icfn_feature_schema=ICFN_SCHEMA,
                rcfn_feature_schema=RCFN_SCHEMA, twin_version=TWIN_VERSION,
                training={"test": True}, unrelaxed=subset)
    assert json.loads((tmp_path / "manifest.json").read_text())[
        "icfn_unrelaxed"]["features"] == list(_SUBSET)
    loaded = load_models(tmp_path).unrelaxed
    assert loaded is not None
    assert loaded.features == _SUBSET
    rng = np.random.default_rng(3)
    x = rng.normal(size=len(ICFN_SCHEMA))
    picked = x[[ICFN_SCHEMA.index(f) for f in _SUBSET]]
    want = 0.5 * (members[0].predict_one(picked) + members[1].predict_one(picked))
    assert loaded.predict_one(x) == pytest.approx(want)
    # Only the named features count: the thermal ones the ensemble leaves out do not.
    other = x.copy()
    other[ICFN_SCHEMA.index("f0_beam4_c")] += 5.0
    assert loaded.predict_one(other) == loaded.predict_one(x)
    np.testing.assert_allclose(loaded.predict(np.stack([x, other])), [want, want])


def test_a_directory_saved_before_the_features_were_named_reads_them_all(
        tmp_path: Path, fitted: tuple[ICFN, ICFN, RCFN]) -> None:
    _save(tmp_path, fitted)
    manifest_path = tmp_path / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    del manifest["icfn_unrelaxed"]["features"]
    manifest_path.write_text(json.dumps(manifest))
    loaded = load_models(tmp_path).unrelaxed
    assert loaded is not None
    assert loaded.features == ICFN_SCHEMA.names


def test_an_ensemble_names_known_features_in_the_schemas_order(
        fitted: tuple[ICFN, ICFN, RCFN]) -> None:
    members = _subset_pair()
    with pytest.raises(ValueError, match="does not have: f0_colour"):
        UnrelaxedIcfn(members, _model(), (*_SUBSET[:-1], "f0_colour"))
    with pytest.raises(ValueError, match="schema's order"):
        UnrelaxedIcfn(members, _model(), tuple(reversed(_SUBSET)))
    with pytest.raises(ValueError, match="read 11 features but it names 9"):
        UnrelaxedIcfn(members, _model(), _SUBSET[:9])
    with pytest.raises(ValueError, match="read 29 features but it names 11"):
        UnrelaxedIcfn((fitted[1],), _model(), _SUBSET)


@pytest.mark.parametrize("damage", ["drop_history", "drop_file", "corrupt", "schema",
                                    "members", "member_arrays", "features_unknown",
                                    "features_count", "features_type", "members_dropped",
                                    "band_level"])
def test_a_damaged_unrelaxed_section_is_refused_in_one_line(
        tmp_path: Path, fitted: tuple[ICFN, ICFN, RCFN], damage: str) -> None:
    _save(tmp_path, fitted)
    manifest_path = tmp_path / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    if damage == "drop_history":
        del manifest["history"]
    elif damage == "drop_file":
        (tmp_path / "history.npz").unlink()
    elif damage == "corrupt":
        (tmp_path / "icfn_unrelaxed.npz").write_bytes(b"not an npz")
    elif damage == "schema":
        manifest["icfn_unrelaxed"]["feature_schema"]["version"] = "other"
    elif damage == "members":
        manifest["icfn_unrelaxed"]["params"] = {"members": "none"}
    elif damage == "features_unknown":
        manifest["icfn_unrelaxed"]["features"][0] = "marker_size_px"
    elif damage == "features_count":  # the members read all 29
        manifest["icfn_unrelaxed"]["features"] = list(_SUBSET)
    elif damage == "features_type":
        manifest["icfn_unrelaxed"]["features"] = "pose"
    elif damage == "members_dropped":  # the file's second member would go unused
        manifest["icfn_unrelaxed"]["params"]["members"] = \
            manifest["icfn_unrelaxed"]["params"]["members"][:1]
    elif damage == "band_level":  # the band's quantile at every frame: 2 has none
        manifest["history"]["params"]["band_level"] = 2.0
    else:  # a third member the file has no arrays for
        members = manifest["icfn_unrelaxed"]["params"]["members"]
        members.append(members[0])
    manifest_path.write_text(json.dumps(manifest))
    with pytest.raises(ModelFileError) as info:
        load_models(tmp_path)
    assert "\n" not in str(info.value)


def _percept(t: float, x: np.ndarray | None) -> SimpleNamespace:
    return SimpleNamespace(t_s=t, features=x, marker=None, thermal=None)


def test_the_estimate_is_the_unrelaxed_icfn_times_the_retained_share(
        fitted: tuple[ICFN, ICFN, RCFN]) -> None:
    icfn, unrelaxed, _ = fitted
    model = _model()
    est = IcfnEstimator(icfn, unrelaxed=UnrelaxedIcfn((unrelaxed,), model))
    twin = LoadingHistory(model)
    for i, t in enumerate(np.arange(0.0, 20.0, 1 / 30)):
        d = min(1e-4 * float(t), 1.5e-3)
        x = _features(d)
        got = est.instantaneous(_percept(float(t), x))  # type: ignore[arg-type]
        twin.advance(float(t), d, 40.0)
        assert got == pytest.approx(max(0.0, unrelaxed.predict_one(x)) * twin.retained())
        if i == 0:
            assert twin.retained() == 1.0
    assert twin.retained() < 0.95  # the history mattered
    assert math.isnan(est.instantaneous(_percept(20.0, None)))  # type: ignore[arg-type]
    est.reset()
    assert est.history is not None
    assert est.history.branches_m is None


def test_an_ensemble_needs_members_that_agree(fitted: tuple[ICFN, ICFN, RCFN]) -> None:
    with pytest.raises(ValueError, match="at least one member"):
        UnrelaxedIcfn((), _model())
    rng = np.random.default_rng(1)
    other = ICFN(hidden_layer_sizes=(4,), max_iter=50).fit(rng.normal(size=(40, 3)),
                                                           rng.normal(size=40))
    with pytest.raises(ValueError, match="different feature counts"):
        UnrelaxedIcfn((fitted[0], other), _model())


def test_relax_and_observer_read_the_history_and_the_baselines_never_do(
        fitted: tuple[ICFN, ICFN, RCFN]) -> None:
    icfn, unrelaxed, rcfn = fitted
    pair = UnrelaxedIcfn((unrelaxed,), _model())
    relax = make_estimator("relax", icfn, rcfn, unrelaxed=pair)
    assert isinstance(relax, RelaxEstimator)
    assert relax.icfn.unrelaxed is pair
    observer = make_estimator("observer", icfn, rcfn, observer=_model(), unrelaxed=pair)
    assert observer.icfn.unrelaxed is pair  # type: ignore[attr-defined]
    assert observer.relax.icfn.unrelaxed is pair  # type: ignore[attr-defined]
    for kind in ("fixed", "icfn"):
        baseline = make_estimator(kind, icfn, rcfn, unrelaxed=pair)
        assert isinstance(baseline, IcfnEstimator)
        assert baseline.unrelaxed is None
    assert isinstance(make_estimator("fixed", icfn, rcfn), FixedEstimator)
    x = _features(1e-3)
    plain = make_estimator("relax", icfn, rcfn)
    assert plain.icfn.instantaneous(_percept(0.0, x)) == max(  # type: ignore[attr-defined]
        0.0, icfn.predict_one(x))


def test_training_leaves_out_rows_that_retain_little_of_their_unrelaxed_force(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from relaxgrip.learning import icfn as icfn_module
    from relaxgrip.learning import training

    monkeypatch.setattr(icfn_module, "ICFN_CANDIDATES",
                        ({"hidden_layer_sizes": (4,), "max_iter": 50},))
    monkeypatch.setattr(training, "UNRELAXED_MEMBERS", 2)
    frames = []
    for episode in range(6):
        # Close over 2 s, hold 300 s, then unload to a tenth within a second.
        t = np.concatenate([np.linspace(0.0, 2.0, 20), np.linspace(10.0, 302.0, 20),
                            [302.5, 303.0]])
        d = np.concatenate([np.linspace(0.0, 1e-3, 20), np.full(20, 1e-3), [5e-4, 1e-4]])
        rows = pd.DataFrame([_features(v) for v in d], columns=list(ICFN_SCHEMA.names))
        rows.insert(0, "t_s", t)
        rows.insert(0, "episode", episode)
        rows["force_n"] = 5000.0 * d
        rows["split"] = "train" if episode < 4 else "val"
        frames.append(rows)
    data = SimpleNamespace(icfn=pd.concat(frames, ignore_index=True))
    shares = retained_shares(data.icfn, _model())
    assert shares.min() < training.MIN_RETAINED_SHARE  # the unloading
    unrelaxed, record = training._fit_unrelaxed(
        data, _model(), 0, ICFN_SCHEMA.names)  # type: ignore[arg-type]
    assert len(unrelaxed.members) == 2
    assert record["rows_left_out"] == int((shares < training.MIN_RETAINED_SHARE).sum()) > 0
    assert record["train_rows"] + record["val_rows"] + record["rows_left_out"] == len(data.icfn)
    # On a subset of the features the members read those alone, and the record names them.
    pose = ICFN_SCHEMA.names[:9]
    subset, record = training._fit_unrelaxed(data, _model(), 0, pose)  # type: ignore[arg-type]
    assert subset.features == pose
    assert record["features"] == list(pose)
    assert all(m.n_features_in_ == 9 for m in subset.members)
    x = _features(1e-3)
    assert subset.predict_one(x) == pytest.approx(
        np.mean([m.predict_one(x[:9]) for m in subset.members]))
    with pytest.raises(InputError, match="marker_size_px"):
        training._fit_unrelaxed(data, _model(), 0, ("marker_size_px",))  # type: ignore[arg-type]
    data.icfn["split"] = "test"
    with pytest.raises(InputError, match="--no-unrelaxed"):
        training._fit_unrelaxed(data, _model(), 0, pose)  # type: ignore[arg-type]

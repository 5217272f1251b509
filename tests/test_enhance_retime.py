"""retime (Bermano et al. 2014, §6): eq. 5 by hand, the eq. 6 DP against brute force, known dynamics, bad input."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import workbench.enhance
from workbench.enhance import RetimeResult, retime
from workbench.enhance.projection import project_segments, sequence_projection


def _smoothstep(t):
    return t * t * (3.0 - 2.0 * t)


def _logistic(centre: float, k: float):
    def c(t):
        f = 1.0 / (1.0 + np.exp(-k * (t - centre)))
        f0 = 1.0 / (1.0 + np.exp(k * centre))
        f1 = 1.0 / (1.0 + np.exp(-k * (1.0 - centre)))
        return (f - f0) / (f1 - f0)

    return c


# known monotone dynamics, none of them linear or smoothstep
CURVES = {
    "ease_in": lambda t: t**3,
    "attack": lambda t: 1.0 - (1.0 - t) ** 3,
    "late": _logistic(0.72, 14.0),
    "early": _logistic(0.28, 12.0),
}


def _transition(a, b, curve, n):
    c = curve(np.linspace(0.0, 1.0, n))
    return a[None] + c[:, None] * (b - a)[None]


def _database(rng, k=12, neutral_start=True):
    """One take per curve (neutral hold → transition → hold → return), plus distractor takes."""
    neutral = np.zeros(k)
    poses, seqs = {}, []
    for name, curve in CURVES.items():
        a = neutral if neutral_start else rng.uniform(0.0, 1.0, k)
        b = rng.uniform(0.0, 1.0, k)
        n = int(rng.integers(25, 46))
        take = np.vstack(
            [
                np.repeat(a[None], 3, axis=0),
                _transition(a, b, curve, n),
                np.repeat(b[None], 4, axis=0),
                _transition(b, a, _smoothstep, 20),
            ]
        )
        poses[name] = (a, b, len(seqs))
        seqs.append(take)
    for _ in range(4):  # distractors: other poses, other timing
        a, b = rng.uniform(0.0, 1.0, k), rng.uniform(0.0, 1.0, k)
        seqs.append(_transition(a, b, CURVES["ease_in"], 30))
        seqs.append(_transition(b, a, CURVES["attack"], 22))
    return seqs, poses


def _rms(x, y):
    return float(np.sqrt(np.mean((np.asarray(x) - np.asarray(y)) ** 2)))


def test_exported():
    assert workbench.enhance.retime is retime
    assert workbench.enhance.RetimeResult is RetimeResult


def test_project_segments_by_hand():
    # α = (0.5, 1) on β = (0,0) → (1,0) → (1,1):
    # segment 0: foot (0.5, 0), weight of β_0 = 0.5, distance 1;
    # segment 1: foot clipped to β_2 = (1, 1), weight of β_1 = 0, distance 0.5
    T, E = project_segments([[0.5, 1.0]], [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    np.testing.assert_allclose(T, [[0.5, 0.0]], atol=1e-12)
    np.testing.assert_allclose(E, [[1.0, 0.5]], atol=1e-12)


def test_project_segments_far_from_origin():
    # the inner-product expansion must not cancel when the data sit far from the origin (a head at z = 1e4)
    rng = np.random.default_rng(0)
    beta = rng.normal(size=(8, 9)) + 1e4
    alpha = beta[3] * 0.3 + beta[4] * 0.7
    T, E = project_segments(alpha[None], beta)
    assert E[0, 3] < 1e-8
    assert T[0, 3] == pytest.approx(0.3, abs=1e-8)


def test_project_segments_matches_a_direct_loop():
    # eq. 5 written out per segment, on a take with a hold (β_2 = β_3) and small steps far from the origin
    rng = np.random.default_rng(7)
    beta = np.cumsum(rng.normal(scale=0.01, size=(9, 15)), axis=0) + 500.0
    beta[3] = beta[2]
    alpha = beta[[1, 4, 7]] + rng.normal(scale=0.005, size=(3, 15))
    T, E = project_segments(alpha, beta)
    for i in range(3):
        for j in range(8):
            d = beta[j] - beta[j + 1]
            t = 0.0 if j == 2 else np.clip((alpha[i] - beta[j + 1]) @ d / (d @ d), 0.0, 1.0)
            assert T[i, j] == pytest.approx(t, abs=1e-6)
            assert E[i, j] == pytest.approx(np.linalg.norm(alpha[i] - (t * beta[j] + (1 - t) * beta[j + 1])), rel=1e-6)


def test_sequence_projection_matches_brute_force():
    rng = np.random.default_rng(1)
    for _ in range(5):
        alpha = rng.normal(size=(3, 4))
        beta = rng.normal(size=(6, 4))
        T, E = project_segments(alpha, beta)
        brute = min(
            sum(E[i, p] for i, p in enumerate(P)) for P in itertools.combinations_with_replacement(range(5), 3)
        )
        P, times, err = sequence_projection(alpha, beta)
        assert err == pytest.approx(brute, rel=1e-12)
        assert np.all(np.diff(P) >= 0)
        assert err == pytest.approx(E[np.arange(3), P].sum(), rel=1e-12)
        np.testing.assert_allclose(times, P + 1.0 - T[np.arange(3), P])


def test_hand_worked_retime():
    # β = 0, 0.25, 1 at times 0, 1, 2; keys 0 → 1. The chord β̂ = 0 → 1 is sampled 9 times (4 per frame of
    # the span): u = 0.125 is stamped at time 0.5 (segment 0: 0.125 / 0.25), u = 0.25 at 1, u = 0.625 at
    # 1 + 0.375 / 0.75 = 1.5; so at uniform times 0, 0.5, 1, 1.5, 2 the progress is 0, 0.125, 0.25, 0.625, 1
    r = retime([np.array([[0.0], [0.25], [1.0]])], [0.0], [1.0], 5)
    np.testing.assert_allclose(r.s, [0.0, 0.125, 0.25, 0.625, 1.0], atol=1e-12)
    np.testing.assert_allclose(r.frames[:, 0], r.s, atol=1e-12)
    np.testing.assert_allclose(r.times, [0.0, 0.5, 1.0, 1.5, 2.0])
    assert r.span == pytest.approx((0.0, 2.0))
    assert r.matched == (0, 0, 2)
    assert r.error == pytest.approx(0.0, abs=1e-12)
    # the same take scaled and shifted, keyed at its ends: the same timing
    r2 = retime([2.0 + 3.0 * np.array([[0.0], [0.25], [1.0]])], [2.0], [5.0], 5)
    np.testing.assert_allclose(r2.s, r.s, atol=1e-12)
    np.testing.assert_allclose(r2.frames[:, 0], 2.0 + 3.0 * r.s, atol=1e-12)


@pytest.mark.parametrize("extend", [False, True])
@pytest.mark.parametrize("neutral_start", [True, False])
@pytest.mark.parametrize("name", list(CURVES))
def test_retimed_inbetweens_follow_the_true_dynamics(name, neutral_start, extend):
    rng = np.random.default_rng(2)
    seqs, poses = _database(rng, neutral_start=neutral_start)
    a, b, index = poses[name]
    # a held-out take of the same expression: slightly different poses, a different length
    a2 = a + 0.01 * rng.normal(size=a.shape)
    b2 = b + 0.01 * rng.normal(size=b.shape)
    n = 37
    truth = _transition(a2, b2, CURVES[name], n)
    r = retime(seqs, a2, b2, n, extend=extend)
    assert r.matched[0] == index
    assert r.choice == "match" and r.error < 0.15 * np.linalg.norm(b2 - a2)  # the same transition: auto keeps it
    u = np.linspace(0.0, 1.0, n)
    linear = _transition(a2, b2, lambda t: t, n)
    ease = _transition(a2, b2, _smoothstep, n)
    err, err_lin, err_ease = _rms(r.frames, truth), _rms(linear, truth), _rms(ease, truth)
    if extend:
        # the whole captured motion: the truth up to resampling
        assert err < 0.1 * min(err_lin, err_ease), (err, err_lin, err_ease)
        assert np.max(np.abs(r.s - CURVES[name](u))) < 0.03
    else:
        # the direct match: a key on a slow tail (noise of 0.01 hides the last per cent) can cut the motion
        # short, so only "better than linear and than ease-in/out" (measured: 0.02-0.76 of the better one)
        assert err < min(err_lin, err_ease), (err, err_lin, err_ease)
    # s: 0 → 1, monotone; the keys are kept exactly
    assert r.s[0] == 0.0 and r.s[-1] == 1.0
    assert np.all(np.diff(r.s) >= 0.0)
    np.testing.assert_array_equal(r.frames[0], a2)
    np.testing.assert_array_equal(r.frames[-1], b2)
    assert r.s.shape == (n,) and r.frames.shape == (n, a.size) and r.times.shape == (n,)


def test_mesh_sequences():
    rng = np.random.default_rng(3)
    nv, k = 40, 5
    base = rng.normal(size=(nv, 3)) + np.array([0.0, 0.0, 100.0])  # far from the origin, like a head in cm
    shapes = rng.normal(scale=0.5, size=(k, nv, 3))
    seqs_w, poses = _database(rng, k=k)
    seqs = [base[None] + np.einsum("tk,kvc->tvc", w, shapes) for w in seqs_w]
    a, b, index = poses["attack"]
    ma = base + np.einsum("k,kvc->vc", a, shapes)
    mb = base + np.einsum("k,kvc->vc", b, shapes)
    n = 24
    r = retime(seqs, ma, mb, n)
    assert r.matched[0] == index
    assert r.frames.shape == (n, nv, 3)
    u = np.linspace(0.0, 1.0, n)
    truth = ma[None] + CURVES["attack"](u)[:, None, None] * (mb - ma)[None]
    lin = ma[None] + u[:, None, None] * (mb - ma)[None]
    assert _rms(r.frames, truth) < 0.1 * _rms(lin, truth)


def test_keys_inside_a_transition_match_a_sub_sequence():
    # keys at 20 % and 80 % of an ease-in take: the span lands inside, s is the renormalised curve
    rng = np.random.default_rng(4)
    a, b = rng.uniform(size=6), rng.uniform(size=6)
    T = 61
    take = _transition(a, b, CURVES["ease_in"], T)
    t = np.linspace(0.0, 1.0, T)
    t0, t1 = 0.2 ** (1 / 3), 0.8 ** (1 / 3)  # where the curve is 0.2 and 0.8
    start, end = a + 0.2 * (b - a), a + 0.8 * (b - a)
    r = retime([take], start, end, 30)
    assert r.span[0] == pytest.approx(t0 * (T - 1), abs=0.05)
    assert r.span[1] == pytest.approx(t1 * (T - 1), abs=0.05)
    assert r.matched[1] <= r.span[0] and r.matched[2] >= r.span[1]
    times = np.linspace(t0, t1, 30)
    expected = (np.interp(times, t, t**3) - 0.2) / 0.6
    assert np.max(np.abs(r.s - expected)) < 0.02
    assert r.error == pytest.approx(0.0, abs=1e-9)


def test_extend_times_the_keys_by_the_whole_motion():
    # keys at 20 % and 80 % of an ease-in take held at both ends: extend grows the span to the whole
    # transition (not into the holds), and s is the take's own curve
    rng = np.random.default_rng(6)
    a, b = rng.uniform(size=6), rng.uniform(size=6)
    T = 41
    take = np.vstack([np.repeat(a[None], 5, axis=0), _transition(a, b, CURVES["ease_in"], T), np.repeat(b[None], 5, axis=0)])
    start, end = a + 0.2 * (b - a), a + 0.8 * (b - a)
    direct = retime([take], start, end, 30)
    r = retime([take], start, end, 30, extend=True)
    assert r.span == (5.0, 45.0)  # the first and last frames of the transition (frame 5 is a, 45 is b)
    assert r.matched == (0, 5, 45)
    assert r.error == direct.error
    np.testing.assert_allclose(r.s, CURVES["ease_in"](np.linspace(0.0, 1.0, 30)), atol=0.01)


def test_order_matters_reverse_keys_match_the_return():
    # A → B with an attack curve, then B → A with ease-in: keys B → A must match the return, with its timing
    rng = np.random.default_rng(5)
    a, b = rng.uniform(size=6), rng.uniform(size=6)
    take = np.vstack([_transition(a, b, CURVES["attack"], 30), _transition(b, a, CURVES["ease_in"], 30)[1:]])
    n = 25
    r = retime([take], b, a, n)
    assert r.span[0] >= 28.9
    np.testing.assert_allclose(r.s, CURVES["ease_in"](np.linspace(0, 1, n)), atol=0.03)
    fwd = retime([take], a, b, n)
    assert fwd.span[1] <= 29.1
    np.testing.assert_allclose(fwd.s, CURVES["attack"](np.linspace(0, 1, n)), atol=0.03)


def test_overshoot_is_not_reproduced():
    # a take that passes the end pose, overshoots by ~2 % and settles back (paper §6.2: the result is made of
    # the keys only): the end matches the first crossing (the tightest span), s stays monotone in [0, 1]
    rng = np.random.default_rng(8)
    a, b = rng.uniform(size=8), rng.uniform(size=8)

    def overshoot(t):
        return 1.0 - np.exp(-6.0 * t) * np.cos(5.0 * t) * (1.0 - t)

    take = _transition(a, b, overshoot, 50)
    first_crossing = np.flatnonzero(overshoot(np.linspace(0.0, 1.0, 50)) >= 1.0)[0]
    r = retime([take], a, b, 40)
    assert first_crossing - 1 <= r.span[1] <= first_crossing
    assert np.all(np.diff(r.s) >= 0.0) and r.s.min() == 0.0 and r.s.max() == 1.0
    # extend runs on to the peak of the overshoot (the progress stops growing there)
    peak = int(np.argmax(overshoot(np.linspace(0.0, 1.0, 50))))
    assert retime([take], a, b, 40, extend=True).span[1] == peak


def test_long_take():
    # a 6000-frame take: the chord oversampling is capped (memory), the timing is still the take's
    a, b = np.zeros(4), np.ones(4)
    take = _transition(a, b, CURVES["late"], 6000)
    r = retime([take], a, b, 12)
    # the first frames differ by ~1e-7 of the motion (the curve is flat there): ties to eq. 5's resolution
    assert r.span[0] <= 5.0 and r.span[1] == pytest.approx(5999.0)
    np.testing.assert_allclose(r.s, CURVES["late"](np.linspace(0.0, 1.0, 12)), atol=0.01)


def test_one_array_is_a_one_sequence_database():
    take = _transition(np.zeros(3), np.ones(3), CURVES["early"], 20)
    r1 = retime(take, np.zeros(3), np.ones(3), 10)
    r2 = retime([take], np.zeros(3), np.ones(3), 10)
    np.testing.assert_array_equal(r1.s, r2.s)


def test_n_frames_two_is_the_keys():
    take = _transition(np.zeros(3), np.ones(3), CURVES["early"], 20)
    r = retime([take], np.zeros(3), np.ones(3), 2)
    np.testing.assert_array_equal(r.s, [0.0, 1.0])


@pytest.mark.parametrize(
    ("args", "word"),
    [
        (([], np.zeros(3), np.ones(3), 5), "database"),
        (([np.zeros((4, 2))], np.zeros(3), np.ones(3), 5), r"database\[0\]"),
        (([np.zeros((4, 3)), np.zeros((1, 3))], np.zeros(3), np.ones(3), 5), r"database\[1\]"),
        (([np.full((4, 3), np.nan)], np.zeros(3), np.ones(3), 5), r"database\[0\].*NaN"),
        (([np.zeros((4, 3))], np.zeros(3), np.ones(4), 5), "end"),
        (([np.zeros((4, 3))], [0.0, np.nan, 0.0], np.ones(3), 5), "start.*NaN"),
        (([np.zeros((4, 3))], np.zeros(3), [1.0, np.inf, 1.0], 5), "end.*NaN"),
        (([np.zeros((4, 3))], np.zeros(3), np.ones(3), 1), "n_frames"),
        (([np.zeros((4, 3))], np.zeros(3), np.ones(3), 2.5), "n_frames"),
        (([np.zeros((4, 3))], np.zeros(3), np.zeros(3), 5), "end"),
        (([np.zeros((4, 2, 2))], np.zeros((2, 2)), np.ones((2, 2)), 5), "start"),
        ((None, np.zeros(3), np.ones(3), 5), "database"),
    ],
)
def test_bad_input_names_the_argument(args, word):
    with pytest.raises(ValueError, match=word):
        retime(*args)


def test_mesh_topology_mismatch():
    with pytest.raises(ValueError, match=r"database\[0\]"):
        retime([np.zeros((5, 10, 3))], np.zeros((12, 3)), np.ones((12, 3)), 5)


def test_no_forward_match():
    # a two-frame database going end → start: every placement of the keys runs backwards in time
    with pytest.raises(ValueError, match="database"):
        retime([np.array([[1.0], [0.0]])], [0.0], [1.0], 5, method="closest")
    # "auto" says so instead: no match, no transition to learn from (2 frames) → an ease curve
    r = retime([np.array([[1.0], [0.0]])], [0.0], [1.0], 5)
    assert r.choice == "ease" and r.matched == (-1, -1, -1) and r.error == np.inf
    np.testing.assert_allclose(r.s, _smoothstep(np.linspace(0.0, 1.0, 5)))


def test_unknown_method():
    with pytest.raises(ValueError, match="method"):
        retime([np.zeros((4, 3))], np.zeros(3), np.ones(3), 5, method="nearest")

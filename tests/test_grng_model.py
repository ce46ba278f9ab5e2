"""Fast unit tests of the bit-exact GRNG model (model/grng.py).

The references here are written independently of the model: L'Ecuyer's lfsr258 C code step by
step with its published decimal constants, and the exact inverse CDF from statistics.NormalDist.
"""

from __future__ import annotations

import math
from pathlib import Path
from statistics import NormalDist

import numpy as np
import pytest
from scipy.special import ndtri

from gpf.config import load_config
from gpf.model.grng import (
    COMPONENTS,
    LFSR258,
    GrngModel,
    condition,
    seed_words,
    uniforms,
)

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ("bot", "odd")
MASK64 = (1 << 64) - 1
SIGN = 1 << 63
# Smallest legal component states of lfsr258: z1 > 1, z2 > 511, z3 > 4095, z4 > 131071,
# z5 > 8388607 (L'Ecuyer 1999); each is 2^(64 - k_j) - 1 for the degrees k = 63, 55, 52, 47, 41.
MINIMUM = (1, 511, 4095, 131071, 8388607)
# Published masks and (q, s, k) shifts of lfsr258, as in L'Ecuyer's C code.
PUBLISHED = (
    (1, 53, 10, 18446744073709551614),
    (24, 50, 5, 18446744073709551104),
    (3, 23, 29, 18446744073709547520),
    (5, 24, 23, 18446744073709420544),
    (3, 33, 8, 18446744073701163008),
)


def lfsr258_reference(state: list[int], n: int) -> list[int]:
    """L'Ecuyer's lfsr258 written out as in the C code (64-bit unsigned arithmetic)."""
    y1, y2, y3, y4, y5 = state
    out = []
    for _ in range(n):
        b = ((((y1 << 1) & MASK64) ^ y1) >> 53)
        y1 = (((y1 & 18446744073709551614) << 10) & MASK64) ^ b
        b = ((((y2 << 24) & MASK64) ^ y2) >> 50)
        y2 = (((y2 & 18446744073709551104) << 5) & MASK64) ^ b
        b = ((((y3 << 3) & MASK64) ^ y3) >> 23)
        y3 = (((y3 & 18446744073709547520) << 29) & MASK64) ^ b
        b = ((((y4 << 5) & MASK64) ^ y4) >> 24)
        y4 = (((y4 & 18446744073709420544) << 23) & MASK64) ^ b
        b = ((((y5 << 3) & MASK64) ^ y5) >> 33)
        y5 = (((y5 & 18446744073701163008) << 8) & MASK64) ^ b
        out.append(y1 ^ y2 ^ y3 ^ y4 ^ y5)
    return out


def _config(name: str, lanes: int | None = None):
    overrides = {"filter.lanes": lanes} if lanes else None
    return load_config(ROOT / "configs" / f"{name}.toml", overrides)


@pytest.fixture(scope="module", params=CONFIGS)
def model(request) -> GrngModel:
    return GrngModel(_config(request.param))


# ---- uniform source ------------------------------------------------------------------------
def test_lfsr258_constants_are_the_published_ones():
    assert tuple(LFSR258) == PUBLISHED
    for (_, _, _, mask), minimum in zip(LFSR258, MINIMUM, strict=True):
        assert mask == MASK64 ^ minimum  # the cleared low bits are exactly the minimum's bits


STATES = {
    "seed0": [condition(w, i) for i, w in enumerate(seed_words(0, 1))],
    "seed1": [condition(w, i) for i, w in enumerate(seed_words(1, 1))],
    "seed_max": [condition(w, i) for i, w in enumerate(seed_words(MASK64, 1))],
    "minimal": [m + 1 for m in MINIMUM],
    "all_ones": [MASK64] * COMPONENTS,
}


@pytest.mark.parametrize("name", STATES)
def test_vectorised_lfsr258_matches_reference_across_blocks(name):
    state = STATES[name]
    n = 10_000  # crosses the 4096-step jump-table block boundary twice
    ref = np.array(lfsr258_reference(state, n), dtype=np.uint64)
    got = uniforms(state, n)
    assert got.dtype == np.uint64
    mismatch = np.nonzero(got != ref)[0]
    assert mismatch.size == 0, f"first mismatch at step {mismatch[:1]}"
    for m in (1, 4095, 4096, 4097, 8193):  # lengths at and around the block edges
        assert np.array_equal(uniforms(state, m), ref[:m])


def test_model_lanes_are_lfsr258_streams_of_their_seed_words():
    model = GrngModel(_config("bot", lanes=2))
    state = model.loaded_state(99)
    u = model.uniforms(5000, state)
    assert u.shape == (5000, 2)
    for lane in range(2):
        ref = lfsr258_reference(state[COMPONENTS * lane: COMPONENTS * (lane + 1)], 5000)
        assert np.array_equal(u[:, lane], np.array(ref, dtype=np.uint64))


# ---- seed conditioning ---------------------------------------------------------------------
@pytest.mark.parametrize("word", [0, 1, 511, 4095, 1 << 63, MASK64, 0x0123456789ABCDEF])
def test_conditioned_components_are_above_their_minimum(word):
    for component, minimum in enumerate(MINIMUM):
        z = condition(word, component)
        assert minimum < z <= MASK64
        # conditioning only sets a bit: every other bit of the word is kept
        assert z & ~(minimum + 1) == word & ~(minimum + 1)


@pytest.mark.parametrize("seed", [0, 1, 12345, MASK64])
def test_loaded_states_are_legal(seed):
    model = GrngModel(_config("odd"))
    state = model.loaded_state(seed)
    assert len(state) == COMPONENTS * model.lanes
    for i, z in enumerate(state):
        assert z > MINIMUM[i % COMPONENTS]


def test_all_zero_seed_words_still_give_a_working_generator():
    model = GrngModel(_config("bot", lanes=2))
    raw = model.normals_raw_from_words([0] * (COMPONENTS * 2), 4000)
    for lane in range(2):
        assert np.unique(raw[:, lane]).size > 3000  # not stuck (an all-zero LFSR would be)
    ref = lfsr258_reference([condition(0, i) for i in range(COMPONENTS)], 4000)
    assert np.array_equal(raw[:, 0], model.from_uniforms(np.array(ref, dtype=np.uint64)))
    with pytest.raises(ValueError):
        model.normals_raw_from_words([0] * COMPONENTS, 10)


# ---- inversion -----------------------------------------------------------------------------
def _place(value: int, shift: int) -> int:
    """value << shift, dropping the bits that would fall below bit 0."""
    return value << shift if shift >= 0 else value >> -shift


def make_word(model: GrngModel, k: int, j: int, x: int, low_ones: bool = False,
              negative: bool = False) -> int:
    """A uniform word whose p (low 63 bits / 2^63) lies in octave k, segment j, offset x.

    In deep octaves the offset's low bits may have no room left; they are dropped.
    """
    seg = model.seg
    top = 62 - k  # the leading one of p
    xshift = top - seg.segment_bits - seg.offset_bits
    m = 1 << top | j << (top - seg.segment_bits) | _place(x, xshift)
    if low_ones and xshift > 0:
        m |= (1 << xshift) - 1
    return m | (SIGN if negative else 0)


def exact_raw(model: GrngModel, word: int) -> float:
    """Q^-1(p/2) in output LSBs for the word's p, by statistics.NormalDist (p > 0)."""
    half_p = math.ldexp(word & (SIGN - 1), -64)
    return -NormalDist().inv_cdf(half_p) * (1 << model.out.frac_bits)


def _octaves(model: GrngModel) -> list[int]:
    k = model.seg.octaves
    return sorted({0, 1, 2, 5, k // 2, k - 3, k - 2, k - 1})


def test_split_follows_the_documented_conventions(model):
    seg = model.seg
    for k in _octaves(model):
        for j in (0, 1, (1 << seg.segment_bits) - 1):
            for x in (0, 1, 1 << (seg.offset_bits - 1), (1 << seg.offset_bits) - 1):
                for negative in (False, True):
                    w = make_word(model, k, j, x, low_ones=True, negative=negative)
                    neg, addr, xo = model.split(np.array([w], dtype=np.uint64))
                    xshift = 62 - k - seg.segment_bits - seg.offset_bits
                    x_seen = x if xshift >= 0 else x >> -xshift << -xshift
                    assert (bool(neg[0]), int(addr[0]), int(xo[0])) == (
                        negative, k << seg.segment_bits | j, x_seen)


def test_inversion_within_one_lsb_of_exact(model):
    seg = model.seg
    words = []
    for k in _octaves(model):
        for j in sorted({0, 1, (1 << seg.segment_bits) // 2, (1 << seg.segment_bits) - 1}):
            for x in (0, 1, 1234, 1 << (seg.offset_bits - 1), (1 << seg.offset_bits) - 1):
                for low_ones in (False, True):
                    words.append(make_word(model, k, j, x, low_ones))
    words += [SIGN - 1, 1 << 62, (1 << 62) - 1]  # p just below 1, p = 1/2 from both sides
    raw = model.from_uniforms(np.array(words, dtype=np.uint64))
    for w, r in zip(words, raw, strict=True):
        exact = exact_raw(model, w)
        assert abs(int(r) - exact) <= 1.0, f"word {w:#018x}: {int(r)} vs exact {exact:.3f}"
        assert r >= 0  # bit 63 clear: positive


def test_inversion_within_one_lsb_everywhere_odd():
    """Every offset of every segment of `odd` (2.4 M points), both edges of each offset's bin."""
    model = GrngModel(_config("odd"))
    seg, frac = model.seg, model.out.frac_bits
    xs = np.arange(1 << seg.offset_bits, dtype=np.int64)
    worst = 0.0
    for addr in range(seg.depth):
        k, j = divmod(addr, 1 << seg.segment_bits)
        mag = model._horner(np.full(xs.shape, addr), xs)
        edges = np.arange((1 << seg.offset_bits) + 1) / (1 << seg.offset_bits)
        p = 2.0 ** -(k + 1) * (1 + (j + edges) / (1 << seg.segment_bits))
        exact = -ndtri(p / 2) * (1 << frac)
        worst = max(worst, float(np.max(np.maximum(np.abs(mag - exact[:-1]),
                                                   np.abs(mag - exact[1:])))))
    # ndtri agrees with NormalDist to far better than an LSB; check one deep point anyway
    assert abs(-ndtri(2.0 ** -38) + NormalDist().inv_cdf(2.0 ** -38)) < 1e-9
    assert worst <= 1.0


def test_beyond_last_octave_and_p_zero_clamp_to_the_table_end(model):
    seg = model.seg
    k_last = seg.octaves - 1
    start = 1 << (62 - k_last)  # first word of the deepest octave: p = 2^-K
    deep = [0, 1, 2, 12345, start >> 1, start - 1]  # p = 0 and p < 2^-K
    raw = model.from_uniforms(np.array(deep + [start], dtype=np.uint64))
    assert np.all(raw == raw[-1])
    assert raw[-1] == model._horner(np.array([k_last << seg.segment_bits]), np.array([0]))[0]
    assert abs(int(raw[-1]) - exact_raw(model, start)) <= 1.0
    neg = model.from_uniforms(np.array([w | SIGN for w in deep], dtype=np.uint64))
    assert np.all(neg == -raw[-1])


def test_flipping_the_sign_bit_negates_exactly(model):
    rng = np.random.default_rng(2024)
    u = rng.integers(0, MASK64, size=20_000, dtype=np.uint64, endpoint=True)
    u = np.concatenate([u, np.array([0, 1, SIGN - 1, 1 << 62], dtype=np.uint64)])
    pos = model.from_uniforms(u & np.uint64(SIGN - 1))
    neg = model.from_uniforms(u | np.uint64(SIGN))
    assert np.array_equal(neg, -pos)
    assert np.all(pos >= 0)
    assert np.array_equal(model.from_uniforms(u ^ np.uint64(SIGN)), -model.from_uniforms(u))


_SWEEPS: dict[str, np.ndarray] = {}


def _sweep(model: GrngModel) -> np.ndarray:
    """Sorted p words across every octave: sampled offsets in every segment, both ends of
    every segment, every offset of three whole segments (the first, the last, the deepest)."""
    if model.cfg.name not in _SWEEPS:
        _SWEEPS[model.cfg.name] = _build_sweep(model)
    return _SWEEPS[model.cfg.name]


def _build_sweep(model: GrngModel) -> np.ndarray:
    seg = model.seg
    xmax = (1 << seg.offset_bits) - 1
    sampled = np.unique(np.linspace(0, xmax, 33).astype(int))
    words = [0, 1]
    for k in range(seg.octaves):
        for j in range(1 << seg.segment_bits):
            words += [make_word(model, k, j, int(x)) for x in sampled]
            words.append(make_word(model, k, j, xmax, low_ones=True))
    last = (1 << seg.segment_bits) - 1
    for k, j in ((0, 0), (0, last), (seg.octaves - 1, 0)):
        words += [make_word(model, k, j, x) for x in range(xmax + 1)]
    return np.unique(np.array(words, dtype=np.uint64))


def test_magnitude_non_increasing_in_p_to_within_one_lsb(model):
    mag = np.abs(model.from_uniforms(_sweep(model)))
    steps = np.diff(mag)  # p increases along the sweep, so |z| must not grow
    assert steps.max() <= 1, f"|z| grows by {steps.max()} LSB somewhere"


@pytest.mark.parametrize(("name", "at_least"), [("bot", 7.8), ("odd", 6.0)])
def test_tail_reach_and_error_bound(name, at_least):
    model = GrngModel(_config(name))
    top = model.from_uniforms(np.array([0, SIGN], dtype=np.uint64))  # p = 0, both signs
    z_max = float(model.out.to_real(top[0]))
    assert z_max >= at_least
    assert top[1] == -top[0]
    assert top[0] <= model.out.max_raw
    # nothing in the sweep goes beyond it
    assert np.abs(model.from_uniforms(_sweep(model))).max() == top[0]
    assert model.max_abs_error() <= 0.75


# ---- lanes and reproducibility -------------------------------------------------------------
def test_lanes_differ_and_seeds_reproduce():
    cfg = _config("bot", lanes=2)
    model = GrngModel(cfg)
    z = model.normals_raw(4000, seed=5)
    assert z.shape == (4000, 2)
    assert np.mean(z[:, 0] == z[:, 1]) < 0.01  # independent streams, not copies or shifts
    assert not np.array_equal(z[1:, 0], z[:-1, 1]) and not np.array_equal(z[:-1, 0], z[1:, 1])
    state = model.loaded_state(5)
    assert state[:COMPONENTS] != state[COMPONENTS:]
    assert np.array_equal(GrngModel(cfg).normals_raw(4000, seed=5), z)  # a fresh model too
    assert not np.array_equal(model.normals_raw(4000, seed=6), z)
    assert np.array_equal(model.normals_raw(100), model.normals_raw(100, seed=cfg.grng.seed))
    assert np.array_equal(model.normals_raw_from_words(seed_words(5, 2), 4000), z)
    assert np.array_equal(model.normals(4000, seed=5), z * model.out.lsb)


@pytest.mark.parametrize("name", ["bot", "odd", "uav", "uav_seed002"])
def test_no_table_entry_rounds_below_zero(name):
    """The inversion's clamp at 0 (grng_icdf.sv's mag_wide < 0) is never reached: the Horner
    value before the clamp, at every ROM address and every offset x (every pair a uniform word
    can select), is >= 0 in each shipped config. equivalent.toml's grng_icdf.sv.j2:118:32 and
    code_holes.toml's clamp entry rest on this."""
    model = GrngModel(_config(name))
    xs = np.arange(1 << model.seg.offset_bits, dtype=np.int64)
    lowest = min(int(model.unclamped_magnitude(np.full(xs.shape, addr), xs).min())
                 for addr in range(model.seg.depth))
    assert lowest >= 0

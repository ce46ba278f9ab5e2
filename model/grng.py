"""Gaussian random number generator: bit-exact model and the constants its RTL is built from.

Method (see README, "GRNG"): per lane, a 64-bit combined Tausworthe generator (L'Ecuyer's
LFSR258, period ~2^258) gives one uniform word per clock. Its top bit is the sign; the other 63
bits are the tail probability p of |z|. Inversion |z| = Q^-1(p/2) is a quadratic per segment:
the segment is chosen by the leading-zero count of p (octave k: p in [2^-(k+1), 2^-k)) and the
next S bits, so segments get finer geometrically towards the tail. Everything here is integer
arithmetic that the generated SystemVerilog repeats step for step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from statistics import NormalDist

import numpy as np

from gpf.config import Config
from gpf.model.fixed import Format, shift_round

MASK64 = (1 << 64) - 1

# LFSR258 (L'Ecuyer 1999, "Tables of maximally equidistributed combined LFSR generators"):
# per component (q, s, k, mask): b = ((z << q) ^ z) >> s; z = ((z & mask) << k) ^ b.
LFSR258 = (
    (1, 53, 10, 0xFFFFFFFFFFFFFFFE),
    (24, 50, 5, 0xFFFFFFFFFFFFFE00),
    (3, 23, 29, 0xFFFFFFFFFFFFF000),
    (5, 24, 23, 0xFFFFFFFFFFFE0000),
    (3, 33, 8, 0xFFFFFFFFFF800000),
)
# A component's state must have a bit set above its mask's cleared bits (z1 > 1, z2 > 511, ...);
# the RTL forces this bit on every seed load, so any 64-bit seed word gives a full-period state.
SEED_FORCE_BIT = (1, 9, 12, 17, 23)
COMPONENTS = len(LFSR258)

LATENCY = 12  # clocks from a uniform draw to its normal sample at the output: 11 stages, the FIFO


def splitmix64(x: int) -> tuple[int, int]:
    """One SplitMix64 step: (new state, output). Expands one user seed into seed words."""
    x = (x + 0x9E3779B97F4A7C15) & MASK64
    z = x
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
    return x, z ^ (z >> 31)


def seed_words(seed: int, lanes: int) -> list[int]:
    """The words a seed load sends, lane 0 component 1 first (5 per lane)."""
    state, words = seed & MASK64, []
    for _ in range(lanes * COMPONENTS):
        state, word = splitmix64(state)
        words.append(word)
    return words


def condition(word: int, component: int) -> int:
    """What the RTL stores when it loads `word` into `component`."""
    return word | (1 << SEED_FORCE_BIT[component])


def lfsr_step(z: int, component: int) -> int:
    q, s, k, mask = LFSR258[component]
    b = (((z << q) & MASK64) ^ z) >> s
    return (((z & mask) << k) & MASK64) ^ b


class _LinearMap:
    """A GF(2)-linear map on 64-bit words, applied to numpy arrays through 8 byte tables."""

    def __init__(self, columns: np.ndarray):
        self.columns = columns.astype(np.uint64)  # image of each unit vector 1 << bit
        tables = np.zeros((8, 256), dtype=np.uint64)
        values = np.arange(256)
        for byte in range(8):
            for bit in range(8):
                tables[byte, (values >> bit) & 1 == 1] ^= self.columns[8 * byte + bit]
        self.tables = tables

    def apply(self, z: np.ndarray) -> np.ndarray:
        out = np.zeros_like(z)
        for byte in range(8):
            out ^= self.tables[byte][(z >> np.uint64(8 * byte)) & np.uint64(0xFF)]
        return out

    def squared(self) -> _LinearMap:
        return _LinearMap(self.apply(self.columns))

    def wide_tables(self) -> np.ndarray:
        """4 tables of 2^16 entries: half the lookups of apply(), for the map used most."""
        low, high = self.tables[0::2], self.tables[1::2]            # bytes 0,2,4,6 / 1,3,5,7
        return (low[:, None, :] ^ high[:, :, None]).reshape(4, 1 << 16)


def _apply_wide(tables: np.ndarray, z: np.ndarray) -> np.ndarray:
    out = tables[0][z & np.uint64(0xFFFF)]
    for half in range(1, 4):
        out ^= tables[half][(z >> np.uint64(16 * half)) & np.uint64(0xFFFF)]
    return out


_BLOCK_LEVELS = 16  # states are produced in blocks of up to 2^16 per numpy operation
_POWERS: dict[int, list[_LinearMap]] = {}
_WIDE: dict[int, np.ndarray] = {}


def _powers(component: int) -> list[_LinearMap]:
    """The maps step^(2^j), j = 0.._BLOCK_LEVELS, for one component (built by squaring)."""
    if component not in _POWERS:
        first = np.array([lfsr_step(1 << bit, component) for bit in range(64)], dtype=np.uint64)
        maps = [_LinearMap(first)]
        for _ in range(_BLOCK_LEVELS):
            maps.append(maps[-1].squared())
        _POWERS[component] = maps
    return _POWERS[component]


def component_states(z0: int, component: int, n: int) -> np.ndarray:
    """States z_1 .. z_n after 1 .. n steps from z0.

    The first block grows by doubling (z_{m+1..2m} = step^m(z_{1..m})), later blocks jump by the
    block length, so the work is a few dozen numpy operations per 2^16 states.
    """
    maps = _powers(component)
    block = np.array([lfsr_step(z0, component)], dtype=np.uint64)
    level = 0
    while len(block) < n and level < _BLOCK_LEVELS:
        block = np.concatenate([block, maps[level].apply(block)])
        level += 1
    out = np.empty(n, dtype=np.uint64)
    out[: min(n, len(block))] = block[:n]
    if n > len(block) and component not in _WIDE:
        _WIDE[component] = maps[level].wide_tables()
    for start in range(len(block), n, len(block)):
        block = _apply_wide(_WIDE[component], block)
        end = min(start + len(block), n)
        out[start:end] = block[: end - start]
    return out


def uniforms(state: list[int], n: int) -> np.ndarray:
    """n uniform words (uint64) from one lane's 5 component states (already conditioned)."""
    out = np.zeros(n, dtype=np.uint64)
    for component, z0 in enumerate(state):
        out ^= component_states(z0, component, n)
    return out


@dataclass(frozen=True)
class Segmentation:
    octaves: int        # K: leading-zero counts 0..K-1 each get their own octave
    segment_bits: int   # S: segments per octave = 2^S
    offset_bits: int    # XW: bits of the offset x inside a segment (a DSP operand)

    @property
    def depth(self) -> int:
        return self.octaves << self.segment_bits


class GrngModel:
    """Bit-exact model of the generated `grng` block for one config."""

    def __init__(self, cfg: Config, lanes: int | None = None):
        """`lanes` overrides cfg.lanes: the filter's GRNG has draws-per-particle x LANES lanes."""
        self.cfg = cfg
        self.lanes = cfg.lanes if lanes is None else lanes
        self.out: Format = cfg.noise
        g = cfg.grng
        self.seg = Segmentation(g.octaves, g.segment_bits, g.offset_bits)
        self.guard_bits = g.guard_bits
        self.coef_frac = self.out.frac_bits + g.guard_bits

    # ---- constants shared with the generator -------------------------------------------
    def reset_state(self) -> list[int]:
        """Conditioned component states after reset: the config's seed, lane 0 first."""
        return self.loaded_state(self.cfg.grng.seed)

    def loaded_state(self, seed: int) -> list[int]:
        return [condition(w, i % COMPONENTS) for i, w in enumerate(self.seed_words(seed))]

    @cached_property
    def lut(self) -> np.ndarray:
        """int64 array (depth, 3): raw c0, c1, c2 per segment, fraction bits coef_frac."""
        seg, nd = self.seg, NormalDist()
        nodes = [0.5 - 0.5 * math.cos((2 * i + 1) * math.pi / 6) for i in range(3)]
        half_bin = 0.5 / (1 << seg.offset_bits)  # x_raw stands for the middle of its bin
        rows = []
        for k in range(seg.octaves):
            for j in range(1 << seg.segment_bits):
                def target(x: float, k: int = k, j: int = j) -> float:
                    p = 2.0 ** -(k + 1) * (1 + (j + x + half_bin) / (1 << seg.segment_bits))
                    return -nd.inv_cdf(p / 2)
                rows.append(_quantised_quadratic(nodes, [target(x) for x in nodes],
                                                 self.coef_frac))
        return np.array(rows, dtype=np.int64)

    @cached_property
    def coef_widths(self) -> tuple[int, int, int]:
        """Signed widths of c0, c1, c2 (one ROM word holds all three)."""
        return tuple(max(_signed_width(int(v)) for v in self.lut[:, i]) for i in range(3))

    @cached_property
    def sum_widths(self) -> tuple[int, int]:
        """Signed widths of the Horner sums s1 = c2 x + c1 and s2 = s1 x + c0.

        s1 is monotone in x, so its extremes over a segment are at x = 0 and x = 1 - 2^-XW;
        s2 is bounded by |s1| + |c0| (x < 1) plus one rounding step.
        """
        xmax = np.full(self.seg.depth, (1 << self.seg.offset_bits) - 1, dtype=np.int64)
        s1_ends = np.stack([self._s1(np.arange(self.seg.depth), x) for x in (0 * xmax, xmax)])
        s1_abs = np.abs(s1_ends).max(axis=0)
        s2_bound = s1_abs + np.abs(self.lut[:, 0]) + 1
        return (max(_signed_width(int(v)) for v in s1_ends.ravel()),
                _signed_width(int(s2_bound.max())))

    def max_abs_error(self, samples_per_segment: int = 64) -> float:
        """Largest |model - exact Q^-1| in output LSBs over sampled offsets of every segment."""
        seg, nd = self.seg, NormalDist()
        xs = np.linspace(0, (1 << seg.offset_bits) - 1, samples_per_segment).astype(np.int64)
        worst = 0.0
        for addr in range(seg.depth):
            k, j = divmod(addr, 1 << seg.segment_bits)
            mag = self._horner(np.full(xs.shape, addr), xs)
            for x_raw, m in zip(xs, mag, strict=True):
                x = (x_raw + 0.5) / (1 << seg.offset_bits)
                p = 2.0 ** -(k + 1) * (1 + (j + x) / (1 << seg.segment_bits))
                exact = -nd.inv_cdf(p / 2) * (1 << self.out.frac_bits)
                worst = max(worst, abs(int(m) - exact))
        return worst

    # ---- the datapath ----------------------------------------------------------------------
    def split(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Uniform words -> (negative, LUT address, offset x) as the RTL's first stage does."""
        seg = self.seg
        negative = (u >> np.uint64(63)).astype(bool)
        m = u & np.uint64((1 << 63) - 1)
        lzc = 63 - _bit_length(m)  # 63 for m == 0
        deep = lzc >= seg.octaves
        shift = np.where(deep, 0, lzc).astype(np.uint64)
        norm = (m << shift) & np.uint64((1 << 63) - 1)  # leading one now at bit 62
        j = (norm >> np.uint64(62 - seg.segment_bits)) & np.uint64((1 << seg.segment_bits) - 1)
        x = (norm >> np.uint64(62 - seg.segment_bits - seg.offset_bits)) & np.uint64(
            (1 << seg.offset_bits) - 1)
        # beyond the last octave: the far end of the table (|z| = 7.9 for 48 octaves)
        addr = np.where(deep, (seg.octaves - 1) << seg.segment_bits,
                        (lzc.astype(np.int64) << seg.segment_bits) + j.astype(np.int64))
        x = np.where(deep, 0, x.astype(np.int64))
        return negative, addr.astype(np.int64), x

    def _s1(self, addr: np.ndarray, x: np.ndarray) -> np.ndarray:
        xw = self.seg.offset_bits
        return shift_round(self.lut[addr, 2] * x, xw, "half_up", width=64 - 2) + self.lut[addr, 1]

    def unclamped_magnitude(self, addr: np.ndarray, x: np.ndarray) -> np.ndarray:
        """((c2 x) + c1) x + c0 in the output format, rounded half up: |z| before the clamp at
        0 (grng_icdf.sv's mag_wide)."""
        xw = self.seg.offset_bits
        s1 = self._s1(addr, x)
        s2 = shift_round(s1 * x, xw, "half_up", width=64 - 2) + self.lut[addr, 0]
        return shift_round(s2, self.guard_bits, "half_up", width=64 - 2)

    def _horner(self, addr: np.ndarray, x: np.ndarray) -> np.ndarray:
        """|z| raw in the output format: ((c2 x) + c1) x + c0, rounded half up, at least 0."""
        return np.maximum(self.unclamped_magnitude(addr, x), 0)

    def from_uniforms(self, u: np.ndarray) -> np.ndarray:
        """Raw normal samples (int64, output format) for uniform words of any shape."""
        negative, addr, x = self.split(u.ravel())
        mag = self._horner(addr, x)
        return np.where(negative, -mag, mag).reshape(u.shape)

    def seed_words(self, seed: int) -> list[int]:
        """The words to send on the seed bus to load `seed`."""
        return seed_words(seed, self.lanes)

    def uniforms(self, n: int, state: list[int]) -> np.ndarray:
        """(n, lanes) uniform words from conditioned component states (5 per lane)."""
        lanes = [uniforms(state[COMPONENTS * lane: COMPONENTS * (lane + 1)], n)
                 for lane in range(self.lanes)]
        return np.stack(lanes, axis=1)

    def normals_raw(self, n: int, seed: int | None = None) -> np.ndarray:
        """(n, lanes) raw samples after reset (seed None) or after loading `seed`."""
        state = self.reset_state() if seed is None else self.loaded_state(seed)
        return self.from_uniforms(self.uniforms(n, state))

    def normals_raw_from_words(self, words: list[int], n: int) -> np.ndarray:
        """(n, lanes) raw samples after the RTL has loaded these seed words."""
        if len(words) != COMPONENTS * self.lanes:
            raise ValueError(f"a seed load is {COMPONENTS * self.lanes} words, got {len(words)}")
        state = [condition(w, i % COMPONENTS) for i, w in enumerate(words)]
        return self.from_uniforms(self.uniforms(n, state))

    def normals(self, n: int, seed: int | None = None) -> np.ndarray:
        """(n, lanes) samples as real numbers."""
        return self.out.to_real(self.normals_raw(n, seed))


_MANY_LEVELS = 10   # many streams: double to 2^10 states each, then jump 2^10 at a time
_WIDE_MANY: dict[int, np.ndarray] = {}


def component_states_many(z0: np.ndarray, component: int, n: int) -> np.ndarray:
    """component_states of many streams of one component at once: z0 (S,) -> (S, n). Every
    stream of a component steps by the same linear map, so the doubling and the jumps act on
    all of them in one numpy operation (the jumps through 16-bit tables: 4 lookups a state)."""
    maps = _powers(component)
    block = np.array([lfsr_step(int(z), component) for z in z0], dtype=np.uint64)[:, None]
    level = 0
    while block.shape[1] < n and level < _MANY_LEVELS:
        block = np.concatenate([block, maps[level].apply(block)], axis=1)
        level += 1
    out = np.empty((len(z0), n), dtype=np.uint64)
    width = block.shape[1]
    out[:, : min(n, width)] = block[:, :n]
    if n > width and component not in _WIDE_MANY:
        _WIDE_MANY[component] = maps[level].wide_tables()
    for start in range(width, n, width):
        block = _apply_wide(_WIDE_MANY[component], block)
        end = min(start + width, n)
        out[:, start:end] = block[:, : end - start]
    return out


class GrngStream:
    """The samples of one or more GRNGs (same config and lanes, one seed each) a chunk at a
    time: `next(n)` continues where the last chunk ended, so the chunks joined are exactly
    `normals_raw` of their total length for each seed."""

    def __init__(self, model: GrngModel, seed: int | None | list[int | None] = None):
        self.model = model
        seeds = seed if isinstance(seed, list) else [seed]
        self.single = not isinstance(seed, list)
        states = [model.reset_state() if s is None else model.loaded_state(s) for s in seeds]
        # (generators x lanes, components) current states
        self.state = np.array(states, dtype=np.uint64).reshape(-1, COMPONENTS)

    def next(self, n: int) -> np.ndarray:
        """(n, lanes) raw samples, or (generators, n, lanes) for a list of seeds."""
        words = np.zeros((len(self.state), n), dtype=np.uint64)
        for component in range(COMPONENTS):
            states = component_states_many(self.state[:, component], component, n)
            words ^= states
            if n:
                self.state[:, component] = states[:, -1]
        lanes = self.model.lanes
        words = words.reshape(len(self.state) // lanes, lanes, n).transpose(0, 2, 1)
        out = self.model.from_uniforms(words)
        return out[0] if self.single else out


def _quantised_quadratic(nodes: list[float], values: list[float], frac: int) -> list[int]:
    """Quadratic through three (Chebyshev) points, coefficients rounded to `frac` bits.

    Pure Python floats, so the same config gives the same LUT on every machine.
    """
    (x0, x1, x2), (y0, y1, y2) = nodes, values
    d01, d12 = (y1 - y0) / (x1 - x0), (y2 - y1) / (x2 - x1)
    c2 = (d12 - d01) / (x2 - x0)
    c1 = d01 - c2 * (x0 + x1)
    c0 = y0 - c1 * x0 - c2 * x0 * x0
    return [math.floor(c * (1 << frac) + 0.5) for c in (c0, c1, c2)]


def _signed_width(v: int) -> int:
    return (v if v >= 0 else ~v).bit_length() + 1


def _bit_length(m: np.ndarray) -> np.ndarray:
    """Exact bit length of uint64 values below 2^63 (0 for 0): the float's exponent, one less
    where rounding to 53 bits carried into the next power of two."""
    _, exp = np.frexp(m.astype(np.float64))
    exp = exp.astype(np.int64)
    carried = (exp > 0) & ((m >> np.maximum(exp - 1, 0).astype(np.uint64)) == 0)
    return exp - carried

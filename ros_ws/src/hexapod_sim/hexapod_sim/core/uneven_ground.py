"""Uneven ground: each foot draws its ground factors at every touchdown (model.md "Uneven
ground").

At its k-th touchdown (k = 0, 1, ...) foot i takes a pair of factors (g_x, g_y)_{i,k} and
keeps it for the whole contact: the engine multiplies K_gx and B_gx by g_x, K_gy and B_gy by
g_y (one factor per direction for stiffness and damping). Each factor is log-normal with
median 1, g = exp(sigma Z), Z standard normal; ``sigma`` (the *spread*) is the standard
deviation of ln g (sigma = 0.2: about 68 % of the touchdowns within x/÷ 1.22 of nominal).

Draws: numpy's default generator, one independent stream per foot spawned from the run's
seed (``SeedSequence(seed).spawn(6)``), two standard normals per touchdown (x then y). A
longer sequence extends a shorter one (the first k pairs do not depend on how many are
drawn), so a run whose feet touched down more often than drawn for is simply rerun with
more draws, and seed k gives every controller the same ground (common random numbers).

The draws travel in an optional tail of the engine's state vector (layout.STATE_SIZE
entries, then):

    s[G0 + i]                      touchdowns of foot i so far (a whole number, float64)
    s[GD0 + 2 (i M + k) + d]       factor d (0: x, 1: y) of touchdown k of foot i

with M = (len(s) - GD0) // 12 pairs per foot. A state without a tail is uniform ground:
the engine's factors are then exactly 1.0, and x * 1.0 == x in IEEE arithmetic, so the
numbers are bit-identical to an engine without this module; so are those of a tail drawn
with sigma = 0 (exp(0) = 1).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hexapod_common.core.jit import njit

from hexapod_common.core.errors import ParameterError
from hexapod_common.core.layout import STATE_SIZE
from hexapod_common.core.params import N_LEGS

#: First tail entry: the touchdown counters, then the factor pairs.
G0 = STATE_SIZE
GD0 = STATE_SIZE + N_LEGS
#: Largest spread accepted (sigma of ln g); exp(3 * 2) = 403x nominal at 3 sigma.
MAX_SPREAD = 2.0
#: Seeds are non-negative integers below this (numpy's SeedSequence takes any size; the
#: bound keeps them exact in JSON and float64).
MAX_SEED = 2 ** 53


@njit(cache=True)
def note_touchdown(s, i, was_in_contact, in_contact):  # type: ignore[no-untyped-def]
    """Count a touchdown of foot i (contact flag 0 -> 1) in the state's tail, if it has one."""
    if s.shape[0] > STATE_SIZE and in_contact != 0.0 and was_in_contact == 0.0:
        s[G0 + i] += 1.0


@njit(cache=True)
def ground_factors(s, i):  # type: ignore[no-untyped-def]
    """(g_x, g_y) of foot i's current (or last) contact; (1.0, 1.0) without a tail.

    Past the last drawn pair the last pair is used; the caller sees it (touchdowns > M,
    :func:`touchdowns`) and reruns with more draws."""
    if s.shape[0] <= STATE_SIZE:
        return 1.0, 1.0
    m = (s.shape[0] - GD0) // (2 * N_LEGS)
    k = int(s[G0 + i]) - 1
    if k < 0:
        k = 0
    elif k >= m:
        k = m - 1
    j = GD0 + 2 * (i * m + k)
    return s[j], s[j + 1]


def check_seed(seed: object, name: str = "ground.seed") -> int:
    """``seed`` as an int in [0, 2^53); ParameterError naming ``name`` otherwise."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) \
            or not 0 <= int(seed) < MAX_SEED:
        raise ParameterError(name, seed, "a whole number in [0, 2^53)")
    return int(seed)


def check_spread(spread: object, name: str = "ground.spread") -> float:
    """``spread`` (sigma of ln g) as a float in [0, MAX_SPREAD]; ParameterError otherwise."""
    if isinstance(spread, bool) or not isinstance(spread, (int, float, np.floating)) \
            or not (math.isfinite(float(spread)) and 0.0 <= float(spread) <= MAX_SPREAD):
        raise ParameterError(name, spread, f"a number in [0, {MAX_SPREAD:g}] (the standard "
                             f"deviation of ln(factor))")
    return float(spread)


@dataclass(frozen=True)
class GroundDraws:
    """The factor pairs of one run: ``factors`` (6, M, 2), foot x touchdown x (g_x, g_y)."""

    seed: int
    spread: float
    factors: np.ndarray

    @classmethod
    def draw(cls, seed: int, spread: float, pairs: int) -> "GroundDraws":
        """``pairs`` touchdowns per foot from seed ``seed`` with spread ``spread`` (sigma)."""
        seed = check_seed(seed)
        spread = check_spread(spread)
        if pairs < 1:
            raise ParameterError("pairs", pairs, "at least 1 draw per foot")
        streams = np.random.SeedSequence(seed).spawn(N_LEGS)
        z = np.stack([np.random.default_rng(ss).standard_normal((pairs, 2)) for ss in streams])
        return cls(seed, spread, np.exp(spread * z))

    @classmethod
    def given(cls, factors: np.ndarray, seed: int = -1, spread: float = math.nan
              ) -> "GroundDraws":
        """Explicit factors (6, M, 2), e.g. a recorded run's (``seed`` -1: not from a seed)."""
        f = np.array(factors, dtype=float)
        if f.ndim != 3 or f.shape[0] != N_LEGS or f.shape[1] < 1 or f.shape[2] != 2 \
                or not np.all(np.isfinite(f)) or not np.all(f > 0):
            raise ParameterError("ground.factors", f"array of shape {f.shape}",
                                 f"({N_LEGS}, M >= 1, 2) finite positive factors")
        return cls(seed, spread, f)

    @property
    def pairs(self) -> int:
        """Drawn touchdowns per foot (M)."""
        return int(self.factors.shape[1])

    def attach(self, state: np.ndarray) -> np.ndarray:
        """A copy of ``state`` (layout.STATE_SIZE entries) with this ground's tail, counters 0."""
        if state.shape != (STATE_SIZE,):
            raise ValueError(f"expected a state vector of {STATE_SIZE} entries, got shape "
                             f"{state.shape}")
        tail = np.zeros(N_LEGS)
        return np.concatenate([state, tail, self.factors.reshape(-1)])

    def used(self, counts: np.ndarray) -> list[np.ndarray]:
        """Per foot, the pairs its ``counts[i]`` touchdowns used ((n_i, 2) arrays)."""
        return [self.factors[i, :min(int(n), self.pairs)] for i, n in enumerate(counts)]


def touchdowns(state: np.ndarray) -> np.ndarray:
    """Touchdowns per foot counted in a state's tail ((6,) ints; zeros without a tail)."""
    if state.shape[0] <= STATE_SIZE:
        return np.zeros(N_LEGS, dtype=np.int64)
    return state[G0:G0 + N_LEGS].astype(np.int64)


@dataclass(frozen=True)
class GroundRecord:
    """What a run on uneven ground used: its draws and each foot's touchdowns."""

    draws: GroundDraws
    touchdowns: tuple[int, ...]

    @property
    def overflowed(self) -> bool:
        """True if a foot touched down more often than pairs were drawn (rerun with more)."""
        return max(self.touchdowns) > self.draws.pairs

    def used(self) -> list[np.ndarray]:
        """Per foot, the (g_x, g_y) pairs of its touchdowns in order ((n_i, 2) arrays)."""
        return self.draws.used(np.array(self.touchdowns))

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: seed, spread, and per foot the factor pairs actually used."""
        return {"seed": self.draws.seed, "spread": self.draws.spread,
                "touchdowns": list(self.touchdowns),
                "factors": [u.tolist() for u in self.used()]}


def pairs_for(duration: float, cycle_time: float) -> int:
    """Draws per foot to start with: eight per gait cycle plus margin (a foot touches down
    about twice per cycle on the base ground; a bouncing foot on hard ground far more often,
    and such a run is rerun with more draws)."""
    return max(16, 8 * (int(math.ceil(duration / cycle_time)) + 2))


__all__ = ["G0", "GD0", "GroundDraws", "GroundRecord", "MAX_SEED", "MAX_SPREAD", "check_seed",
           "check_spread", "ground_factors", "note_touchdown", "pairs_for", "touchdowns"]

"""Light codes: binary sequences flashed by the whole projector image.

Cameras recording the floor see each code as the mean brightness of their frames;
correlating that signal with the code finds where the sequence starts and ends in
every video. Maximum-length sequences (m-sequences, from a linear-feedback shift
register; ``scipy.signal.max_len_seq``) have a single sharp periodic autocorrelation
peak. The start and end codes are two different m-sequences of the same length,
chosen so that each correlates weakly with every shift of itself and of the other
one, framed by black frames as they are projected.
"""

from __future__ import annotations

import itertools
from functools import cache

import numpy as np

from calibproj import _core

MIN_DEGREE = 3
MAX_DEGREE = 8
# Black frames (bits 0) on either side of a code when scoring candidate codes: what a
# decoder correlates against around the code.
_CONTEXT_BITS = 16


# One light code as projected (bits, frames_per_bit, first_frame; frame_count,
# last_frame, frame_levels()): the core's type, which the sync reads.
LightCode = _core.sync.LightCode


def _m_sequence(degree: int, taps: tuple[int, ...]) -> np.ndarray | None:
    """The LFSR sequence for ``taps``, or None if it is not maximum-length."""
    from scipy.signal import max_len_seq

    bits, _ = max_len_seq(degree, taps=list(taps))
    signed = 2.0 * bits - 1.0
    # An m-sequence's periodic autocorrelation is -1 at every non-zero shift.
    spectrum = np.abs(np.fft.rfft(signed)) ** 2
    periodic = np.fft.irfft(spectrum, n=len(signed))
    return bits.astype(np.uint8) if np.allclose(periodic[1:], -1.0, atol=1e-6) else None


def _worst_correlation(template: np.ndarray, projected: np.ndarray) -> float:
    """Largest correlation of ``template`` against ``projected`` framed by black, in
    +-1 levels, leaving out the exact alignment when both are the same code."""
    framed = np.concatenate([np.zeros(_CONTEXT_BITS), projected, np.zeros(_CONTEXT_BITS)])
    scores = np.correlate(2.0 * framed - 1.0, 2.0 * template - 1.0, mode="valid")
    if template is projected:
        scores[_CONTEXT_BITS] = -np.inf
    return float(scores.max())


@cache
def code_pair(degree: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Start and end codes of ``2**degree - 1`` bits.

    Among the m-sequences of that degree with up to three feedback taps, the pair
    whose worst sidelobe (each code against its own shifts and against the other
    code) is lowest; ties go to the first pair found, so the choice is deterministic.
    """
    if not MIN_DEGREE <= degree <= MAX_DEGREE:
        raise ValueError(f"light code degree must be in [{MIN_DEGREE}, {MAX_DEGREE}], got {degree}")
    candidates = []
    for count in range(1, 4):
        for taps in itertools.combinations(range(1, degree), count):
            bits = _m_sequence(degree, taps)
            if bits is not None:
                candidates.append(bits)
    best, best_score = None, np.inf
    for start, end in itertools.permutations(candidates, 2):
        score = max(_worst_correlation(start, start), _worst_correlation(end, end),
                    _worst_correlation(start, end), _worst_correlation(end, start))
        if score < best_score:
            best, best_score = (start, end), score
    if best is None:
        raise ValueError(f"no two distinct m-sequences of degree {degree}")
    return tuple(int(b) for b in best[0]), tuple(int(b) for b in best[1])

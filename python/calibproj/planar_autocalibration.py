"""Focal lengths of cameras that see one plane, in closed form (planar autocalibration).

Every camera maps the floor to its image by a homography H (floor coordinates to
pixels centred on the principal point). The floor's two circular points I and its
conjugate lie, in every image, on that camera's image of the absolute conic
omega = diag(1, 1, f^2) (square pixels, known principal point), so for each camera

    (h1 . I)^2 + (h2 . I)^2 + f^2 (h3 . I)^2 = 0        (h_k: rows of H)

a complex equation, two real ones. The circular points are shared: in any frame of the
floor they are I = (1, z2, z3) up to scale, four real unknowns, (1, i, 0) in a metric
frame. Given I, each camera's f^2 is the least-squares solution of its equation, in
closed form; I itself is found by Gauss-Newton on the four unknowns, starting from the
frame the floor was reconstructed in (metric but for the nominal focal lengths' error).
Four cameras or more are needed (2 N equations, N + 4 unknowns), or fewer when some
focal lengths are known (``known``): then I follows from those cameras.

This gives the self-calibration (``calibproj.self_calibration``) a start that does not
depend on the focal lengths the user guessed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

MIN_POINTS = 8  # per camera, for its floor homography
GAUSS_NEWTON_ITERATIONS = 30


@dataclass(frozen=True)
class PlanarAutocalibration:
    """Focal lengths (pixels) found per camera, the floor's circular point in the frame
    used, and each camera's normalised residual (about 0 when consistent)."""

    focal: dict[str, float]
    residual: dict[str, float]
    circular_point: np.ndarray  # (3,) complex, first entry 1


def focal_lengths(homographies: Mapping[str, np.ndarray], known: Mapping[str, float] | None = None
                  ) -> PlanarAutocalibration:
    """The focal length of every camera whose focal is not in ``known``, from its floor
    homography (floor frame -> pixels centred on its principal point).

    Raises ValueError when the cameras cannot determine them (fewer equations than
    unknowns) or when a homography is degenerate.
    """
    known = dict(known or {})
    names = list(homographies)
    H = {name: _normalised(np.asarray(homographies[name], dtype=float), name) for name in names}
    unknown = [name for name in names if name not in known]
    if 2 * len(names) < len(unknown) + 4:
        raise ValueError(f"planar autocalibration: {len(names)} camera(s) with {len(unknown)} unknown focal "
                         f"length(s) give {2 * len(names)} equations for {len(unknown) + 4} unknowns")
    x = np.array([0.0, 1.0, 0.0, 0.0])  # z2 = i, z3 = 0: a metric frame of the floor
    for _ in range(GAUSS_NEWTON_ITERATIONS):
        r = _residuals(x, H, known)
        J = _jacobian(x, H, known)
        step, *_ = np.linalg.lstsq(J, -r, rcond=None)
        x = x + step
        if np.linalg.norm(step) < 1e-12 * max(1.0, np.linalg.norm(x)):
            break
    I = _circular_point(x)
    focal, residual = {}, {}
    for name in names:
        p, q = _conic_terms(H[name], I)
        f2 = known[name] ** 2 if name in known else _best_f2(p, q)
        residual[name] = float(abs(p + f2 * q) / max(abs(p), 1e-300))
        if name not in known and f2 > 0:
            focal[name] = float(np.sqrt(f2))
    return PlanarAutocalibration(focal, residual, I)


def _normalised(H: np.ndarray, name: str) -> np.ndarray:
    if H.shape != (3, 3) or not np.all(np.isfinite(H)):
        raise ValueError(f"camera {name}: expected a finite 3x3 homography")
    scale = np.linalg.norm(H)
    if scale == 0 or abs(np.linalg.det(H)) < 1e-12 * scale**3:
        raise ValueError(f"camera {name}: degenerate floor homography")
    return H / scale


def _circular_point(x: np.ndarray) -> np.ndarray:
    return np.array([1.0, x[0] + 1j * x[1], x[2] + 1j * x[3]])


def _conic_terms(H: np.ndarray, I: np.ndarray) -> tuple[complex, complex]:
    """(h1.I)^2 + (h2.I)^2 and (h3.I)^2."""
    a, b, c = H @ I
    return a * a + b * b, c * c


def _best_f2(p: complex, q: complex) -> float:
    """The real f^2 >= 0 minimising |p + f^2 q| (a negative one would let a real point,
    a degenerate "circular point", satisfy the equations)."""
    denominator = abs(q) ** 2
    return max(float(-(p * np.conj(q)).real / denominator), 0.0) if denominator > 0 else 0.0


def _residuals(x: np.ndarray, H: Mapping[str, np.ndarray], known: Mapping[str, float]) -> np.ndarray:
    """Per camera the real and imaginary parts of its equation, each focal length
    eliminated (or known), normalised by the size of its terms."""
    I = _circular_point(x)
    out = []
    for name, homography in H.items():
        p, q = _conic_terms(homography, I)
        f2 = known[name] ** 2 if name in known else _best_f2(p, q)
        value = (p + f2 * q) / max(abs(p), 1e-300)
        out += [value.real, value.imag]
    return np.array(out)


def _jacobian(x: np.ndarray, H: Mapping[str, np.ndarray], known: Mapping[str, float]) -> np.ndarray:
    """Central differences: four unknowns, the residuals a few dozen."""
    columns = []
    for k in range(len(x)):
        step = np.zeros_like(x)
        step[k] = 1e-7 * max(1.0, abs(x[k]))
        columns.append((_residuals(x + step, H, known) - _residuals(x - step, H, known)) / (2 * step[k]))
    return np.column_stack(columns)

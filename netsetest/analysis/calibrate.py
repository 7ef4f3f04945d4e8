"""``netsetest calibrate``: the smallest model-mismatch bound that covers a plant's e_k on training drives.

For each training drive (a manoeuvre, at a steering amplitude where it has one), seed and signal family the plant is driven exactly as the vehicle role drives
it (:class:`~netsetest.models.drive.Drive`) and every e_k = x_{k+1} − (Ā_k x_k + B̄_k u_k + D̄_k w_k) is
collected.  Two bounds cover all of them, each enlarged by the stated margin:

- the box: |e_m| ≤ (1 + margin) · max_k |e_m,k|;
- the ellipsoid: the minimum-area origin-centred ellipse {e: eᵀE⁻¹e ≤ 1} around the e_k (Khachiyan's
  algorithm on the symmetric set ±e_k, to relative tolerance :data:`MVEE_TOL`, then scaled so that every
  e_k lies inside), its semi-axes enlarged by (1 + margin).

Where the package has a simpler model of the same car, the same drives on it say how much of e_k each
cause contributes (:func:`simpler_mismatch`): the multi-body model without its suspension and roll is the
single-track drift model, and that without its tyres' nonlinearity is the single track with linear tyres
of the same slope (``single-track-linear``), whose T-S model is the same.

A bound calibrated on some manoeuvres is only an assumption on others: the collector checks it on every
step of every run and attributes a miss beyond it to "model mismatch" (docs/plant.md, "Calibration").
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from netsetest.config.schema import Scenario
from netsetest.models.drive import Drive
from netsetest.models.manoeuvres import WITH_AMPLITUDE, DriveSpec
from netsetest.models.plant import PlantKind
from netsetest.models.signals import SignalKind
from netsetest.models.uncertainty import DEFAULT_MARGIN, ModelUncertainty

# the same car with one cause of mismatch less at each step down (their derived T-S models are the same)
SIMPLER: dict[PlantKind, tuple[PlantKind, ...]] = {
    "ts": (),
    "single-track-linear": (),
    "single-track": ("single-track-linear",),
    "multi-body": ("single-track", "single-track-linear"),
}
MVEE_TOL = 1e-7
MVEE_MAX_ITER = 10_000


@dataclass(frozen=True)
class DriveMismatch:
    """The e_k of one training drive."""

    drive: DriveSpec  # the manoeuvre, with its steering amplitude where it has one
    signals: SignalKind
    seed: int
    e: np.ndarray  # (steps, NX)

    @property
    def max_abs(self) -> np.ndarray:
        return np.abs(self.e).max(axis=0) if len(self.e) else np.zeros(2)


@dataclass(frozen=True)
class Calibration:
    drives: list[DriveMismatch]
    margin: float
    box: ModelUncertainty
    ellipsoid: ModelUncertainty

    def covered(self, bound: ModelUncertainty) -> float:
        """Fraction of the training e_k inside ``bound`` (1.0 for both calibrated bounds)."""
        es = np.vstack([d.e for d in self.drives])
        return float(np.mean([bound.holds(e) for e in es]))


def drive_mismatch(sc: Scenario, signals: SignalKind, seed: int) -> DriveMismatch:
    """e_0..e_{K−1} of one run's truth (no estimator runs)."""
    drive = Drive(sc, signals, seed)
    es = [d.e for d in (drive.step(k) for k in range(sc.steps)) if d.e is not None]
    spec = DriveSpec(sc.manoeuvre, sc.steer_high if sc.manoeuvre in WITH_AMPLITUDE else None)
    return DriveMismatch(spec, signals, seed, np.array(es))


def origin_mvee(points: np.ndarray) -> np.ndarray:
    """E of the minimum-volume ellipsoid {eᵀE⁻¹e ≤ 1} centred at 0 containing ``points`` (m, n).

    Khachiyan's algorithm on the symmetric set ±points (whose minimum ellipsoid is centred at 0), then
    E scaled up so that every point satisfies eᵀE⁻¹e ≤ 1 exactly (the iteration stops at a tolerance)."""
    pts = np.vstack([points, -points])
    m, n = pts.shape
    if np.linalg.matrix_rank(pts) < n:
        raise ValueError("the mismatch samples span fewer than two directions: no ellipsoid is bounded")
    u = np.full(m, 1.0 / m)
    for _ in range(MVEE_MAX_ITER):
        X = pts.T @ (u[:, None] * pts)  # Σ u_i p_i p_iᵀ
        g = np.einsum("ij,jk,ik->i", pts, np.linalg.inv(X), pts)  # p_iᵀ X⁻¹ p_i
        j = int(np.argmax(g))
        step = (g[j] - n) / (n * (g[j] - 1.0))
        if step < MVEE_TOL:
            break
        u *= 1.0 - step
        u[j] += step
    E = n * (pts.T @ (u[:, None] * pts))
    worst = float(np.max(np.einsum("ij,jk,ik->i", pts, np.linalg.inv(E), pts)))
    return E * max(worst, 1.0)


def calibrate(
    scenarios: Sequence[Scenario],
    seeds: Sequence[int],
    signals: Sequence[SignalKind],
    margin: float = DEFAULT_MARGIN,
    progress: Callable[[int, int], None] | None = None,
) -> Calibration:
    """The box and ellipsoid bounds covering every e_k of every (scenario, seed, signals) drive."""
    if margin < 0:
        raise ValueError(f"margin must be ≥ 0, got {margin}")
    runs = [(sc, s, sig) for sc in scenarios for s in seeds for sig in signals]
    drives = []
    for n, (sc, seed, sig) in enumerate(runs):
        drives.append(drive_mismatch(sc, sig, seed))
        if progress is not None:
            progress(n + 1, len(runs))
    es = np.vstack([d.e for d in drives])
    scale = 1.0 + margin
    box = ModelUncertainty.box(np.maximum(np.abs(es).max(axis=0), np.finfo(float).tiny) * scale)
    ellipsoid = ModelUncertainty.ellipsoid(origin_mvee(es) * scale * scale)
    return Calibration(drives, margin, box, ellipsoid)


def simpler_mismatch(
    scenarios: Sequence[Scenario],
    seeds: Sequence[int],
    signals: Sequence[SignalKind],
    progress: Callable[[int, int], None] | None = None,
) -> dict[PlantKind, list[DriveMismatch]]:
    """The same drives on each simpler model of the car (:data:`SIMPLER`), plant by plant."""
    out: dict[PlantKind, list[DriveMismatch]] = {}
    runs = [(plant, sc, s, sig) for plant in SIMPLER[scenarios[0].plant] for sc in scenarios for s in seeds for sig in signals]
    for n, (plant, sc, seed, sig) in enumerate(runs):
        out.setdefault(plant, []).append(drive_mismatch(dataclasses.replace(sc, plant=plant), sig, seed))
        if progress is not None:
            progress(n + 1, len(runs))
    return out


def max_by_drive(drives: Sequence[DriveMismatch]) -> dict[str, np.ndarray]:
    """max_k |e_k| per drive label (a manoeuvre at its amplitude), over seeds and signals, in first-seen order."""
    out: dict[str, np.ndarray] = {}
    for d in drives:
        out[d.drive.label] = np.maximum(out.get(d.drive.label, np.zeros(2)), d.max_abs)
    return out


def with_uncertainty(sc: Scenario, bound: ModelUncertainty | None) -> Scenario:
    """The scenario with another declared mismatch bound (e.g. a calibrated one, or a halved one)."""
    return dataclasses.replace(sc, uncertainty=bound)


__all__ = [
    "SIMPLER",
    "Calibration",
    "DriveMismatch",
    "calibrate",
    "drive_mismatch",
    "max_by_drive",
    "origin_mvee",
    "simpler_mismatch",
    "with_uncertainty",
]

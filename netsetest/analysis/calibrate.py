"""``netsetest calibrate``: the smallest model-mismatch bound that covers a plant's e_k on training drives.

For each training drive (a manoeuvre, at a steering amplitude where it has one), seed and signal family the plant is driven exactly as the vehicle role drives
it (:class:`~netsetest.models.drive.Drive`) and every e_k = x_{k+1} − (Ā_k x_k + B̄_k u_k + D̄_k w_k) is
collected.  Two bounds cover all of them, each enlarged by the stated margin:

- the box: |e_m| ≤ (1 + margin) · max_k |e_m,k|;
- the ellipsoid: the minimum-area origin-centred ellipse {e: eᵀE⁻¹e ≤ 1} around the e_k (Khachiyan's
  algorithm on the symmetric set ±e_k, to relative tolerance :data:`~netsetest.models.uncertainty.MVEE_TOL`, then scaled so that every
  e_k lies inside), its semi-axes enlarged by (1 + margin).

Where the package has a simpler model of the same car, the same drives on it say how much of e_k each
cause contributes (:func:`simpler_mismatch`): the multi-body model without its suspension and roll is the
single-track drift model, and that without its tyres' nonlinearity is the single track with linear tyres
of the same slope (``single-track-linear``), whose T-S model is the same.

Beside e_k each drive reports what bounds it in practice (:class:`DriveEnvelope`): its peak lateral
acceleration, yaw rate, sideslip and steering rate and its speed range.

With an operating envelope (:func:`envelope_sweep`, ``calibrate --envelope --ay-max A --speed LO-HI``) the
drives are chosen to fill it: a step steer and a sine with dwell at speeds across the range, each at
amplitudes up to a little beyond the one whose peak lateral acceleration reaches ``ay_max`` (found by
bisection), and the bound covers the e_k of every transition inside the envelope (those outside it are
left out: the bound is declared for the envelope, and the collector attributes a step outside it as such).

A bound calibrated on some manoeuvres is only an assumption on others: the collector checks it on every
step of every run and attributes a miss beyond it to "model mismatch", or to "outside the operating
envelope" where the car had left the declared one (docs/plant.md, "Calibration").
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from netsetest.config.schema import Scenario, check_envelope_speeds
from netsetest.models.drive import Drive
from netsetest.models.envelope import OperatingEnvelope
from netsetest.models.manoeuvres import WITH_AMPLITUDE, DriveSpec, ManoeuvreName
from netsetest.models.plant import PlantKind
from netsetest.models.signals import SignalKind, SpeedProfile
from netsetest.models.uncertainty import DEFAULT_MARGIN, HOLDS_RTOL, ModelUncertainty, origin_mvee
from netsetest.models.vehicle import KMH

# the same car with one cause of mismatch less at each step down (their derived T-S models are the same)
SIMPLER: dict[PlantKind, tuple[PlantKind, ...]] = {
    "ts": (),
    "single-track-linear": (),
    "single-track": ("single-track-linear",),
    "multi-body": ("single-track", "single-track-linear"),
}
SWEEP_MANOEUVRES: tuple[ManoeuvreName, ...] = ("step-steer", "sine-dwell")  # steered by an amplitude: the envelope's training
SWEEP_SPEEDS = 3  # speeds across the envelope's range: both ends and the middle
# amplitudes, as fractions of the one whose steering alone reaches ay_max: the last overfills the envelope
# (the worst-case wind moves the tyres' load too), and the transitions beyond it are left out of the bound
SWEEP_FRACTIONS = (1 / 3, 2 / 3, 1.0, 1.2)
SEARCH_SIGNALS: tuple[SignalKind, ...] = ("paper",)  # the amplitude search's wind: the paper's, the gentle one
BISECTION_STEPS = 10  # the amplitude reaching ay_max to 2⁻¹⁰ of the bracket's width (0.5 mrad)
SEARCH_S = 4.0  # [s] of each drive the bisection looks at: the sine with dwell ends at 3.1 s, a step steer settles by then
SWEEP_S = 5.0  # [s] of each training drive (at most the topology's steps): the sweep's manoeuvres are over by then
AMPLITUDE_MAX = 0.5  # [rad] the bracket's upper end: the driver's steering limit (manoeuvres.DELTA_MAX)


@dataclass(frozen=True)
class DriveEnvelope:
    """What one drive did, as the operating envelope measures it (the transitions k → k+1)."""

    ay_peak: float  # largest |a_y| the tyres carried [m/s²] (Plant.transition_ay)
    r_peak: float  # largest |r| [rad/s]
    beta_peak: float  # largest |β| [rad]
    speed_kmh: tuple[float, float]  # slowest, fastest
    steer_rate_peak: float  # largest |δ_k − δ_k−1|/τs [rad/s]

    def merged(self, other: DriveEnvelope) -> DriveEnvelope:
        return DriveEnvelope(
            max(self.ay_peak, other.ay_peak),
            max(self.r_peak, other.r_peak),
            max(self.beta_peak, other.beta_peak),
            (min(self.speed_kmh[0], other.speed_kmh[0]), max(self.speed_kmh[1], other.speed_kmh[1])),
            max(self.steer_rate_peak, other.steer_rate_peak),
        )


@dataclass(frozen=True)
class DriveMismatch:
    """The e_k of one training drive, with what the car did on each transition."""

    drive: DriveSpec  # the manoeuvre, with its steering amplitude where it has one
    signals: SignalKind
    seed: int
    e: np.ndarray  # (steps, NX)
    ay: np.ndarray  # (steps,) a_y of each transition [m/s²]
    speed: np.ndarray  # (steps,) v_k [m/s]
    x: np.ndarray  # (steps, NX) x_k
    u: np.ndarray  # (steps,) δ_k [rad]
    tau_s: float
    speed_kmh: float | None = None  # the speed held, where a sweep chose it (part of the label)

    @property
    def max_abs(self) -> np.ndarray:
        return np.abs(self.e).max(axis=0) if len(self.e) else np.zeros(2)

    @property
    def label(self) -> str:
        return self.drive.label if self.speed_kmh is None else f"{self.drive.label} at {self.speed_kmh:g} km/h"

    def inside(self, envelope: OperatingEnvelope | None) -> np.ndarray:
        """(steps,) bool: the transitions inside ``envelope`` (None: all)."""
        if envelope is None:
            return np.ones(len(self.e), dtype=bool)
        return np.array([envelope.holds(a, v) for a, v in zip(self.ay, self.speed)], dtype=bool)

    @property
    def envelope(self) -> DriveEnvelope:
        if not len(self.e):
            return DriveEnvelope(0.0, 0.0, 0.0, (0.0, 0.0), 0.0)
        rate = np.abs(np.diff(self.u)).max() / self.tau_s if len(self.u) > 1 else 0.0
        kmh = self.speed / KMH
        return DriveEnvelope(
            float(np.abs(self.ay).max()),
            float(np.abs(self.x[:, 1]).max()),
            float(np.abs(self.x[:, 0]).max()),
            (float(kmh.min()), float(kmh.max())),
            float(rate),
        )


@dataclass(frozen=True)
class Calibration:
    drives: list[DriveMismatch]
    margin: float
    box: ModelUncertainty
    ellipsoid: ModelUncertainty
    envelope: OperatingEnvelope | None = None  # the bounds cover the transitions inside it (None: every one)

    def samples(self) -> np.ndarray:
        """(m, NX) every training e_k the bounds cover."""
        return np.vstack([d.e[d.inside(self.envelope)] for d in self.drives])

    def covered(self, bound: ModelUncertainty) -> float:
        """Fraction of the training e_k inside ``bound`` (1.0 for both calibrated bounds)."""
        return float(np.mean([bound.holds(e) for e in self.samples()]))


def drive_mismatch(sc: Scenario, signals: SignalKind, seed: int, speed_kmh: float | None = None) -> DriveMismatch:
    """e_0..e_{K−1} of one run's truth and what the car did (no estimator runs)."""
    drive = Drive(sc, signals, seed)
    steps = [d for d in (drive.step(k) for k in range(sc.steps)) if d.e is not None]
    spec = DriveSpec(sc.manoeuvre, sc.steer_high if sc.manoeuvre in WITH_AMPLITUDE else None)
    return DriveMismatch(
        spec,
        signals,
        seed,
        np.array([d.e for d in steps]).reshape(-1, 2),
        np.array([d.ay for d in steps], dtype=float),
        np.array([d.speed for d in steps], dtype=float),
        np.array([d.x for d in steps]).reshape(-1, 2),
        np.array([d.u for d in steps], dtype=float),
        sc.tau_s,
        speed_kmh,
    )


def calibrate(
    scenarios: Sequence[Scenario],
    seeds: Sequence[int],
    signals: Sequence[SignalKind],
    margin: float = DEFAULT_MARGIN,
    progress: Callable[[int, int], None] | None = None,
    envelope: OperatingEnvelope | None = None,
) -> Calibration:
    """The box and ellipsoid bounds covering every e_k of every (scenario, seed, signals) drive (with
    ``envelope``: of every transition inside it).  A scenario from :func:`envelope_sweep` is labelled with
    the speed it holds."""
    if margin < 0:
        raise ValueError(f"margin must be ≥ 0, got {margin}")
    runs = [(sc, s, sig) for sc in scenarios for s in seeds for sig in signals]
    drives = []
    for n, (sc, seed, sig) in enumerate(runs):
        drives.append(drive_mismatch(sc, sig, seed, sc.speed.mean_kmh if envelope is not None else None))
        if progress is not None:
            progress(n + 1, len(runs))
    cal = Calibration(drives, margin, ModelUncertainty.box((1.0, 1.0)), ModelUncertainty.box((1.0, 1.0)), envelope)
    es = cal.samples()
    if not len(es):
        raise ValueError("no transition of the training drives lies inside the envelope: nothing to calibrate on")
    scale = 1.0 + margin
    box = ModelUncertainty.box(np.maximum(np.abs(es).max(axis=0), np.finfo(float).tiny) * scale)
    ellipsoid = ModelUncertainty.ellipsoid(origin_mvee(es) * scale * scale)
    return dataclasses.replace(cal, box=box, ellipsoid=ellipsoid)


def at_speed(sc: Scenario, kmh: float, manoeuvre: ManoeuvreName, amplitude: float) -> Scenario:
    """The scenario driving ``manoeuvre`` at amplitude ``amplitude`` [rad], holding ``kmh``."""
    return dataclasses.replace(
        sc, manoeuvre=manoeuvre, steer_high=amplitude, steer_low=min(sc.steer_low, amplitude), speed=SpeedProfile(kmh, 0.0, sc.speed.period_s)
    )


def peak_ay(sc: Scenario, signals: Sequence[SignalKind]) -> float:
    """The largest |a_y| of seed 0's drive of ``sc`` over the signal families."""
    return max(float(np.abs(drive_mismatch(sc, sig, 0).ay).max(initial=0.0)) for sig in signals)


def amplitude_for(sc: Scenario, kmh: float, manoeuvre: ManoeuvreName, envelope: OperatingEnvelope, signals: Sequence[SignalKind]) -> float:
    """The largest steering amplitude [rad] whose drive (seed 0, every signal family) keeps |a_y| ≤ ay_max
    at ``kmh``, by bisection on [0, AMPLITUDE_MAX] (a_y grows with the amplitude until the tyres saturate)."""
    lo, hi = 0.0, AMPLITUDE_MAX
    short = dataclasses.replace(sc, steps=min(sc.steps, round(SEARCH_S / sc.tau_s)))
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        try:
            inside = peak_ay(at_speed(short, kmh, manoeuvre, mid), signals) <= envelope.ay_max
        except ArithmeticError:  # the car spun and the integration failed: far outside
            inside = False
        lo, hi = (mid, hi) if inside else (lo, mid)
    return lo


def envelope_speeds(envelope: OperatingEnvelope) -> list[float]:
    """SWEEP_SPEEDS speeds [km/h] spread evenly over the envelope's range (one where it is a point)."""
    lo, hi = envelope.speed_kmh
    return [lo] if hi == lo else [float(v) for v in np.linspace(lo, hi, SWEEP_SPEEDS)]


def envelope_sweep(sc: Scenario, envelope: OperatingEnvelope, progress: Callable[[int, int], None] | None = None) -> list[Scenario]:
    """The training drives that fill ``envelope``: each of SWEEP_MANOEUVRES at each of the envelope's speeds,
    at SWEEP_FRACTIONS of the amplitude whose peak |a_y| reaches ay_max (with the paper's wind).  ValueError where the envelope's
    speeds leave the topology's model range (the vehicle could not publish them for scheduling)."""
    p = sc.model.params
    check_envelope_speeds(envelope, p.vx_min / KMH, p.vx_max / KMH)
    plan = [(kmh, m) for kmh in envelope_speeds(envelope) for m in SWEEP_MANOEUVRES]
    drive = dataclasses.replace(sc, steps=min(sc.steps, round(SWEEP_S / sc.tau_s)))
    out = []
    for n, (kmh, m) in enumerate(plan):
        top = amplitude_for(sc, kmh, m, envelope, SEARCH_SIGNALS)
        out += [at_speed(drive, kmh, m, top * f) for f in SWEEP_FRACTIONS if top * f > 0]
        if progress is not None:
            progress(n + 1, len(plan))
    if not out:
        raise ValueError(f"no amplitude keeps |a_y| ≤ {envelope.ay_max:g} m/s² (the wind alone exceeds it): raise --ay-max")
    return out


def simpler_mismatch(
    scenarios: Sequence[Scenario],
    seeds: Sequence[int],
    signals: Sequence[SignalKind],
    progress: Callable[[int, int], None] | None = None,
    swept: bool = False,
) -> dict[PlantKind, list[DriveMismatch]]:
    """The same drives on each simpler model of the car (:data:`SIMPLER`), plant by plant (``swept``: the
    drives of :func:`envelope_sweep`, labelled with their speed as :func:`calibrate` labels them)."""
    out: dict[PlantKind, list[DriveMismatch]] = {}
    runs = [(plant, sc, s, sig) for plant in SIMPLER[scenarios[0].plant] for sc in scenarios for s in seeds for sig in signals]
    for n, (plant, sc, seed, sig) in enumerate(runs):
        out.setdefault(plant, []).append(drive_mismatch(dataclasses.replace(sc, plant=plant), sig, seed, sc.speed.mean_kmh if swept else None))
        if progress is not None:
            progress(n + 1, len(runs))
    return out


def max_by_drive(drives: Sequence[DriveMismatch]) -> dict[str, np.ndarray]:
    """max_k |e_k| per drive label (a manoeuvre at its amplitude, and speed where swept), over seeds and
    signals, in first-seen order."""
    out: dict[str, np.ndarray] = {}
    for d in drives:
        out[d.label] = np.maximum(out.get(d.label, np.zeros(2)), d.max_abs)
    return out


def envelope_by_drive(drives: Sequence[DriveMismatch]) -> dict[str, DriveEnvelope]:
    """What each drive label did, over seeds and signals, in first-seen order."""
    out: dict[str, DriveEnvelope] = {}
    for d in drives:
        out[d.label] = out[d.label].merged(d.envelope) if d.label in out else d.envelope
    return out


# ---------------------------------------------------------------- from recorded drives (calibrate --logs)


@dataclass(frozen=True)
class LogRecording:
    """One recorded drive on the run's steps 0..K (logs/drive.py, streamed): what ``calibrate --logs`` reads of it."""

    path: str
    tau_s: float
    x_ref: np.ndarray  # (K+1, NX) the reference's β, r (NaN where there is none)
    u: np.ndarray  # (K+1,) road-wheel angle [rad]
    speed: np.ndarray  # (K+1,) the logged speed [m/s]
    vx: np.ndarray  # (K+1,) the speed the model is scheduled with (the logged one held inside the model's range)
    y: dict[int, np.ndarray]  # node → (K+1,) its logged reading (NaN: none)
    healthy: dict[int, np.ndarray]  # node → (K+1,) bool: declared fault-free there
    accuracy: np.ndarray  # (NX,) the reference's half-widths


def log_recording(sc: Scenario) -> LogRecording:
    """Every step of ``sc``'s log (its steps decided: logs/drive.py with_log_steps); LogError where it has no reference."""
    from netsetest.logs.drive import LogDrive
    from netsetest.logs.readers import LogError

    assert sc.log is not None
    if sc.log.mapping.r is None:
        raise LogError(f"{sc.log.mapping.path}: no [reference]: calibrating from a log needs the reference's β and r")
    drive = LogDrive(sc)
    steps = [drive.step(k) for k in range(sc.steps + 1)]
    nan2 = np.full(2, np.nan)
    return LogRecording(
        sc.log.path,
        sc.tau_s,
        np.array([d.x_ref if d.x_ref is not None else nan2 for d in steps]),
        np.array([d.u for d in steps]),
        np.array([d.speed for d in steps]),
        np.array([d.vx for d in steps]),
        {i: np.array([np.nan if d.y_log[i] is None else d.y_log[i] for d in steps]) for i in sc.ids},
        {i: np.array([d.healthy[i] for d in steps]) for i in sc.ids},
        np.asarray(sc.log.mapping.accuracy, dtype=float),
    )


@dataclass(frozen=True)
class LoggedMismatch:
    """The transitions k → k+1 of a recorded drive with the reference at both ends: e_k = x_{k+1} − Ā_k x_k − B̄_k u_k
    (the wind taken as 0: the log does not know it, so the bound covers it too) known to lie in the box
    ``centre`` ± ``half``, the reference's accuracy a carried through the model (half = a + |Ā_k| a), with the
    transition's |a_y| = v r (as the run measures it) and speed."""

    centre: np.ndarray  # (m, NX)
    half: np.ndarray  # (m, NX)
    ay: np.ndarray  # (m,)
    speed: np.ndarray  # (m,) [m/s]


def logged_mismatch(sc: Scenario, rec: LogRecording) -> LoggedMismatch:
    """e_k's boxes of the drive's transitions with the reference at both ends (module doc of :class:`LoggedMismatch`)."""
    ok = ~np.isnan(rec.x_ref).any(axis=1)
    ks = np.flatnonzero(ok[:-1] & ok[1:])
    centre, half = np.zeros((ks.size, 2)), np.zeros((ks.size, 2))
    for n, k in enumerate(ks):
        a, b, _ = sc.model.blend(sc.model.weights(rec.vx[k]))
        centre[n] = rec.x_ref[k + 1] - a @ rec.x_ref[k] - b[:, 0] * rec.u[k]
        half[n] = rec.accuracy + np.abs(a) @ rec.accuracy
    return LoggedMismatch(centre, half, rec.speed[ks] * rec.x_ref[ks, 1], rec.speed[ks])


@dataclass(frozen=True)
class SensorNoise:
    """A sensor's noise v = (ỹ − C x)/Dv over the steps its log declares it healthy (f = 0), known to lie within
    ``v_centre`` ± ``v_half`` per step (the reference's accuracy through C); ``steps``: how many."""

    node: int
    steps: int
    v_centre: np.ndarray  # (steps,)
    v_half: float

    @property
    def worst(self) -> float:
        """max |v| the reference allows on these steps (0 where there are none)."""
        return float((np.abs(self.v_centre) + self.v_half).max()) if self.steps else 0.0


def sensor_noise(sc: Scenario, rec: LogRecording) -> dict[int, SensorNoise]:
    """Each sensor's noise over its healthy steps with a reading and the reference."""
    out = {}
    for i in sc.ids:
        sen = sc.node(i).sensor
        use = rec.healthy[i] & ~np.isnan(rec.y[i]) & ~np.isnan(rec.x_ref).any(axis=1)
        v = (rec.y[i][use] - rec.x_ref[use] @ sen.C) / sen.Dv
        out[i] = SensorNoise(i, int(use.sum()), v, float(np.abs(sen.C) @ rec.accuracy / abs(sen.Dv)))
    return out


@dataclass(frozen=True)
class LogCalibration:
    """What ``calibrate --logs`` derives from training drives: the mismatch bounds (box, ellipsoid) holding every
    transition's e_k box, the operating envelope they covered, and each sensor's noise bound R (v² ≤ R) over its
    healthy stretches, every one enlarged by the margin (R: its half-width √R)."""

    logs: list[str]
    margin: float
    box: ModelUncertainty
    ellipsoid: ModelUncertainty
    envelope: OperatingEnvelope
    R: dict[int, float]  # node → the noise bound (None-free: a sensor with no healthy step is refused)
    transitions: int
    noise_steps: dict[int, int]


def calibrate_logs(scenarios: Sequence[Scenario], margin: float = DEFAULT_MARGIN, progress: Callable[[int, int], None] | None = None) -> LogCalibration:
    """The bounds and the envelope of the training drives (one scenario per log, steps decided); ValueError where
    they hold no transition with the reference at both ends, or a sensor no healthy step."""
    if margin < 0:
        raise ValueError(f"margin must be ≥ 0, got {margin}")
    mism, noise = [], []
    for n, sc in enumerate(scenarios):
        rec = log_recording(sc)
        mism.append(logged_mismatch(sc, rec))
        noise.append(sensor_noise(sc, rec))
        if progress is not None:
            progress(n + 1, len(scenarios))
    centre, half = np.vstack([m.centre for m in mism]), np.vstack([m.half for m in mism])
    if not len(centre):
        raise ValueError("no transition of the logs has the reference at both ends: nothing to calibrate on")
    R, counts = {}, {}
    for i in scenarios[0].ids:
        counts[i] = sum(ns[i].steps for ns in noise)
        if not counts[i]:
            raise ValueError(f"node {i}: no step declared healthy with a reading and the reference: its noise bound cannot be calibrated")
        R[i] = (max(ns[i].worst for ns in noise) * (1 + margin)) ** 2
    return LogCalibration(
        [sc.log.path for sc in scenarios if sc.log is not None],
        margin,
        ModelUncertainty.covering_boxes("box", centre, half, margin),
        ModelUncertainty.covering_boxes("ellipsoid", centre, half, margin),
        OperatingEnvelope.covering(np.concatenate([m.ay for m in mism]), np.concatenate([m.speed for m in mism])),
        R,
        len(centre),
        counts,
    )


@dataclass(frozen=True)
class HeldOutLog:
    """A held-out drive against a calibration, as ``calibrate --envelope``'s held-out drives are judged: its
    transitions inside and outside the envelope, and for each set whether e_k's box lies inside the box bound, may
    lie outside it (the reference cannot tell) or certainly does; per sensor, its healthy steps whose noise is
    inside, may be outside, or certainly is outside the calibrated R."""

    path: str
    inside: dict[str, int]  # inside the envelope: "inside" / "overlap" / "disjoint" → transitions
    outside: dict[str, int]  # outside it
    noise: dict[int, dict[str, int]]  # node → the same three → healthy steps


def check_held_out(sc: Scenario, cal: LogCalibration) -> HeldOutLog:
    """One held-out drive against ``cal`` (:class:`HeldOutLog`)."""
    rec = log_recording(sc)
    m = logged_mismatch(sc, rec)
    inside: dict[str, int] = dict.fromkeys(("inside", "overlap", "disjoint"), 0)
    outside = dict(inside)
    for c, h, ay, v in zip(m.centre, m.half, m.ay, m.speed):
        (inside if cal.envelope.holds(float(ay), float(v)) else outside)[cal.box.box_relation(c, h)] += 1
    noise = {}
    for i, ns in sensor_noise(sc, rec).items():
        bound = np.sqrt(cal.R[i]) * (1 + HOLDS_RTOL)
        lo, hi = np.maximum(np.abs(ns.v_centre) - ns.v_half, 0.0), np.abs(ns.v_centre) + ns.v_half
        noise[i] = {"inside": int((hi <= bound).sum()), "overlap": int(((hi > bound) & (lo <= bound)).sum()), "disjoint": int((lo > bound).sum())}
    return HeldOutLog(rec.path, inside, outside, noise)


def with_uncertainty(sc: Scenario, bound: ModelUncertainty | None) -> Scenario:
    """The scenario with another declared mismatch bound (e.g. a calibrated one, or a halved one)."""
    return dataclasses.replace(sc, uncertainty=bound)


__all__ = [
    "SIMPLER",
    "Calibration",
    "HeldOutLog",
    "LogCalibration",
    "LogRecording",
    "LoggedMismatch",
    "SensorNoise",
    "calibrate_logs",
    "check_held_out",
    "log_recording",
    "logged_mismatch",
    "sensor_noise",
    "DriveEnvelope",
    "DriveMismatch",
    "amplitude_for",
    "calibrate",
    "drive_mismatch",
    "envelope_by_drive",
    "envelope_sweep",
    "max_by_drive",
    "origin_mvee",
    "simpler_mismatch",
    "with_uncertainty",
]

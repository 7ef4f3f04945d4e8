"""Manoeuvres: the steering and speed reference a topology selects (``[vehicle] manoeuvre``; docs/plant.md).

- ``paper``: the paper's random steering u_k = low + (high − low)·rand and its sine speed profile;
- ``step-steer``: straight for 1 s, then the road-wheel angle ``[steering] high`` held (ISO 7401's shape);
- ``sine-dwell``: the ESC test's shape (FMVSS 126): a 0.7 Hz sine of amplitude ``high`` from t = 1 s, held
  500 ms at its second peak, then the last quarter period and straight again;
- ``double-lane-change``: the ISO 3888-1 course (15 m entry, 30 m offset 3.5 m, 25 m in the offset lane,
  25 m back, exit) followed by a pure-pursuit driver;
- ``lap``: a closed oval (600 m straights, 350 m half-turns, 3.4 km) followed by pure pursuit while the
  speed reference sweeps the model's scheduling range (the ``[speed]`` sine profile).

Speed: ``paper`` and ``lap`` follow the ``[speed]`` sine profile; the others hold ``[speed] mean_kmh``.
A manoeuvre whose speed reference leaves the model's [vx_min, vx_max] is refused at load.

Pure pursuit (Coulter 1992): the driver aims at the course point a look-ahead distance
l_d = max(L_D_MIN, T_LOOK·v) ahead and steers δ = atan(2 (l_f + l_r) sin α / l_d), α the angle of that
point seen from the vehicle's heading; δ is clipped to ±DELTA_MAX.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from netsetest.models.plant import PlantState
from netsetest.models.signals import SpeedProfile
from netsetest.models.vehicle import KMH

ManoeuvreName = Literal["paper", "step-steer", "sine-dwell", "double-lane-change", "lap"]
MANOEUVRES: tuple[ManoeuvreName, ...] = ("paper", "step-steer", "sine-dwell", "double-lane-change", "lap")
SINE_SPEED: tuple[ManoeuvreName, ...] = ("paper", "lap")  # follow the [speed] sine; the others hold its mean
START_S = 1.0  # straight driving before a step steer or a sine with dwell
SINE_DWELL_HZ = 0.7  # FMVSS 126
DWELL_S = 0.5
L_D_MIN = 8.0  # [m] shortest look-ahead of the driver
T_LOOK = 0.6  # [s] look-ahead time of the driver
DELTA_MAX = 0.5  # [rad] the driver's steering limit
STEERING_MAX_RAD = 1.0  # |δ_f| [rad] anywhere (a topology's [steering], an amplitude): beyond ±57° no tyre model of a road car holds
COURSE_SPACING_M = 0.5
LAP_STRAIGHT_M = 600.0
LAP_RADIUS_M = 350.0


def _constant(v_kmh: float) -> SpeedProfile:
    return SpeedProfile(v_kmh, 0.0, 1.0)


@dataclass
class PurePursuit:
    """Follows the polyline ``course`` (N, 2) [m]; ``closed``: the course is a loop."""

    course: np.ndarray
    wheelbase: float
    closed: bool = False
    progress: int = 0  # index of the last nearest course point (the search only looks ahead)

    def steer(self, st: PlantState) -> float:
        X, Y, psi = st.pose
        n = len(self.course)
        window = np.arange(self.progress, self.progress + 400) % n if self.closed else np.arange(self.progress, min(n, self.progress + 400))
        d = np.hypot(self.course[window, 0] - X, self.course[window, 1] - Y)
        self.progress = int(window[int(np.argmin(d))])
        look = max(L_D_MIN, T_LOOK * st.speed)
        ahead = self.progress
        for _ in range(n):
            nxt = (ahead + 1) % n if self.closed else min(n - 1, ahead + 1)
            if nxt == ahead or math.hypot(self.course[nxt, 0] - X, self.course[nxt, 1] - Y) > look:
                ahead = nxt
                break
            ahead = nxt
        tx, ty = self.course[ahead]
        alpha = math.atan2(ty - Y, tx - X) - psi
        alpha = math.atan2(math.sin(alpha), math.cos(alpha))
        ld = max(math.hypot(tx - X, ty - Y), 1e-6)
        return float(np.clip(math.atan(2 * self.wheelbase * math.sin(alpha) / ld), -DELTA_MAX, DELTA_MAX))


def double_lane_change_course(length_m: float) -> np.ndarray:
    """ISO 3888-1 centreline: 15 m at y = 0, a 30 m transition to y = 3.5 m, 25 m there, a 25 m transition
    back, then straight (to ``length_m``); the transitions are cosine-smoothed."""
    xs = np.arange(0.0, max(length_m, 200.0), COURSE_SPACING_M)

    def ramp(x: np.ndarray, x0: float, dx: float) -> np.ndarray:
        s = np.clip((x - x0) / dx, 0.0, 1.0)
        return 0.5 - 0.5 * np.cos(np.pi * s)

    ys = 3.5 * (ramp(xs, 15.0, 30.0) - ramp(xs, 70.0, 25.0))
    return np.column_stack([xs, ys])


def lap_course() -> np.ndarray:
    """A closed oval, counter-clockwise from the origin heading along +x: LAP_STRAIGHT_M straights joined
    by half-turns of LAP_RADIUS_M (lateral acceleration 3.2 m/s² at 120 km/h)."""
    n_straight = int(LAP_STRAIGHT_M / COURSE_SPACING_M)
    n_bend = int(math.pi * LAP_RADIUS_M / COURSE_SPACING_M)
    xs = np.linspace(0.0, LAP_STRAIGHT_M, n_straight, endpoint=False)
    ang = np.linspace(-math.pi / 2, math.pi / 2, n_bend, endpoint=False)
    bottom = np.column_stack([xs, np.zeros_like(xs)])
    right = np.column_stack([LAP_STRAIGHT_M + LAP_RADIUS_M * np.cos(ang), LAP_RADIUS_M + LAP_RADIUS_M * np.sin(ang)])
    top = np.column_stack([LAP_STRAIGHT_M - xs, np.full_like(xs, 2 * LAP_RADIUS_M)])
    left = np.column_stack([-LAP_RADIUS_M * np.cos(ang), LAP_RADIUS_M - LAP_RADIUS_M * np.sin(ang)])
    return np.vstack([bottom, right, top, left])


@dataclass
class Manoeuvre:
    """One run's steering and speed reference; :meth:`steer` is called once per step, in step order."""

    name: ManoeuvreName
    speed: SpeedProfile
    amplitude: float  # [rad] step steer, sine with dwell
    wheelbase: float
    driver: PurePursuit | None = field(default=None)

    @classmethod
    def build(cls, name: ManoeuvreName, speed: SpeedProfile, amplitude: float, wheelbase: float, duration_s: float) -> Manoeuvre:
        profile = speed if name in SINE_SPEED else _constant(speed.mean_kmh)
        driver = None
        if name == "double-lane-change":
            driver = PurePursuit(double_lane_change_course(speed.mean_kmh * KMH * duration_s + 50.0), wheelbase)
        elif name == "lap":
            driver = PurePursuit(lap_course(), wheelbase, closed=True)
        return cls(name, profile, amplitude, wheelbase, driver)

    def steer(self, t: float, st: PlantState, drawn: float) -> float:
        """δ_k [rad] held over the next sampling interval; ``drawn`` is the paper's random draw of this step."""
        if self.name == "paper":
            return drawn
        if self.name == "step-steer":
            return self.amplitude if t >= START_S else 0.0
        if self.name == "sine-dwell":
            return self.amplitude * sine_with_dwell(t - START_S)
        assert self.driver is not None
        return self.driver.steer(st)


AMPLITUDE_SEP = "@"  # a drive "sine-dwell@0.03": the manoeuvre with [steering] high = 0.03 rad
WITH_AMPLITUDE: tuple[ManoeuvreName, ...] = ("paper", "step-steer", "sine-dwell")  # steered by [steering] high


@dataclass(frozen=True)
class DriveSpec:
    """A manoeuvre, and optionally its steering amplitude [rad] over the topology's ``[steering] high``
    (the paper's draw range's upper end, the step, the sine's amplitude); the drivers' manoeuvres take none."""

    manoeuvre: ManoeuvreName
    amplitude: float | None = None

    @classmethod
    def parse(cls, token: str) -> DriveSpec:
        """``name`` or ``name@amplitude``; ValueError naming what is wrong."""
        name, sep, amp = token.partition(AMPLITUDE_SEP)
        if name not in MANOEUVRES:
            raise ValueError(f"unknown manoeuvre {name!r}; choose from {', '.join(MANOEUVRES)}")
        if not sep:
            return cls(name)
        if name not in WITH_AMPLITUDE:
            raise ValueError(f"{name} takes no amplitude: its driver steers (amplitudes: {', '.join(WITH_AMPLITUDE)})")
        try:
            value = float(amp)
        except ValueError:
            raise ValueError(f"{token}: the amplitude must be a number of radians, got {amp!r}") from None
        if not math.isfinite(value) or value <= 0:
            raise ValueError(f"{token}: the amplitude must be a positive number of radians")
        if value > STEERING_MAX_RAD:  # the option's fault, not the topology's [steering] high it overrides
            raise ValueError(f"{token}: the amplitude must be at most {STEERING_MAX_RAD:g} rad (a road car's steering range)")
        return cls(name, value)

    @property
    def label(self) -> str:
        return self.manoeuvre if self.amplitude is None else f"{self.manoeuvre}{AMPLITUDE_SEP}{self.amplitude:g}"


def steering_range(name: ManoeuvreName, low: float, high: float) -> tuple[float, float]:
    """Every δ_k the manoeuvre can command: what a node accepts as u_{k−1} (others are dropped)."""
    if name == "paper":
        return low, high
    if name in ("step-steer", "sine-dwell"):
        return -abs(high), abs(high)
    return -DELTA_MAX, DELTA_MAX


def sine_with_dwell(t: float) -> float:
    """The normalised FMVSS 126 steering shape: sin(2π f t) up to 3/4 period, −1 for DWELL_S, the last
    quarter, then 0 (t < 0: 0)."""
    period = 1.0 / SINE_DWELL_HZ
    if t < 0:
        return 0.0
    if t < 0.75 * period:
        return math.sin(2 * math.pi * SINE_DWELL_HZ * t)
    if t < 0.75 * period + DWELL_S:
        return -1.0
    t2 = t - DWELL_S
    if t2 < period:
        return math.sin(2 * math.pi * SINE_DWELL_HZ * t2)
    return 0.0


__all__ = ["steering_range", "DriveSpec", "MANOEUVRES", "Manoeuvre", "ManoeuvreName", "PurePursuit", "sine_with_dwell"]

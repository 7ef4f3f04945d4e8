"""``netsetest log-example DIR``: the synthetic example drives of docs/your-log.md, reproducibly.

No real drive can be downloaded here, so the example is made: the CommonRoad car of ``paper6_car`` (the ``plant``
extra: models/plant.py) drives its manoeuvre (models/drive.py, the same truth a simulated run has), and what a car's
loggers would have recorded is written in every format the readers take (logs/write.py): each yaw-rate sensor's
reading with a constant bias (the car's sensor's, the same in every drive) and Gaussian noise (together clipped inside its declared noise bound, so that the
declared bound holds, as the tutorial's verdict checks), its stamps a little before the step in MDF4 and the bags
(a logger's jitter), the speed and the road-wheel angle, and an INS reference of β and r with uniform errors inside
its stated accuracy.  Every file says it is synthetic (a CSV's first column name cannot, so its mapping and the
README beside it do).  The same seed writes the same drive.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from netsetest.config.schema import Scenario, load_topology
from netsetest.logs.write import WRITE_FORMATS, DriveTable, log_path, mapping_toml, write_log
from netsetest.models.drive import Drive

EXAMPLE_TOPOLOGY = "paper6_car"  # the car and the sensors' profiles the example is drawn with
INS_ACCURACY = (math.radians(0.15), math.radians(0.1))  # β 0.15°, r 0.1 °/s: an INS of automotive test grade
BIAS_SHARE, NOISE_SHARE, CLIP_SHARE = 0.3, 0.2, 0.95  # of a sensor's noise bound |Dv|√R: bias, σ, and the clip of both
CAR_SEED = 0xB1A5  # the example car's sensors: their biases are the same in every drive
LOG_START_S = 1.0  # the logger's clock at step 0 (a bag's stamps cannot be negative)
JITTER_S = 0.002  # a logger's stamps fall up to this before the step
NOTE = (
    "SYNTHETIC drive, not a real car's: netsetest log-example drew it from CommonRoad vehicle 2 (paper6_car), "
    "readings with bias and noise inside each sensor's declared bound, an INS reference within ±0.15° (β), ±0.1 °/s (r)"
)


def sensor_biases(sc: Scenario) -> dict[int, float]:
    """Each sensor's constant bias: the car's, the same in every drive (a sensor's property, not a drive's)."""
    car = np.random.default_rng(CAR_SEED)
    return {n.id: car.uniform(-BIAS_SHARE, BIAS_SHARE) * abs(n.sensor.Dv) * math.sqrt(n.sensor.R) for n in sc.nodes}


def example_drive(seconds: float, seed: int, accuracy: tuple[float, float] = INS_ACCURACY, steer_high: float | None = None) -> DriveTable:
    """The drive: ``seconds`` of paper6_car's car at its τs (module doc); ``accuracy``: the reference's errors lie
    within it (0: the reference is the truth); ``steer_high``: the manoeuvre's steering amplitude (default: the
    topology's)."""
    sc0 = load_topology(EXAMPLE_TOPOLOGY)
    steps = round(seconds / sc0.tau_s)
    sc = load_topology(EXAMPLE_TOPOLOGY, steps=steps, steer_high=steer_high)
    drive = Drive(sc, "paper", seed)
    rng = np.random.default_rng([seed, 0x10C])
    rows = [drive.step(k) for k in range(steps + 1)]
    x = np.array([d.x for d in rows])
    t = LOG_START_S + np.arange(steps + 1) * sc.tau_s
    yaw, stamps = {}, {}
    for n, bias in sensor_biases(sc).items():
        sen = sc.node(n).sensor
        bound = abs(sen.Dv) * math.sqrt(sen.R)
        err = np.clip(bias + rng.normal(0.0, NOISE_SHARE * bound, t.size), -CLIP_SHARE * bound, CLIP_SHARE * bound)
        yaw[n] = x @ sen.C + err  # the sensor's own output y (its unit), without a fault: the run injects the profile's
        stamps[n] = t - rng.uniform(0.0, JITTER_S, t.size)
    a = np.array(accuracy)
    ref = x + rng.uniform(-1.0, 1.0, x.shape) * a
    return DriveTable(
        t=t,
        speed=np.array([d.speed for d in rows]),
        steering=np.array([d.u for d in rows]),
        yaw=yaw,
        beta=ref[:, 0],
        r=ref[:, 1],
        yaw_t=stamps,
        description=NOTE,
    )


def write_examples(directory: Path, seconds: float, seed: int) -> list[Path]:
    """The drive in every format, each with its mapping, and a README saying what they are; the paths written."""
    directory.mkdir(parents=True, exist_ok=True)
    d = example_drive(seconds, seed)
    flat = DriveTable(d.t, d.speed, d.steering, d.yaw, d.beta, d.r, description=d.description)  # one time base: CSV, Parquet
    out = []
    for fmt in WRITE_FORMATS:
        log = write_log(flat if fmt in ("csv", "parquet") else d, log_path(directory, "drive", fmt), fmt)
        mapping = directory / f"drive_{fmt.replace('rosbag-', '')}.map.toml"
        mapping.write_text(mapping_toml(d, fmt, INS_ACCURACY, note=NOTE))
        out += [log, mapping]
    readme = directory / "README.md"
    readme.write_text(
        f"# Example drives (synthetic)\n\n{NOTE}.\n\nMade by `netsetest log-example {directory} --seconds {seconds:g} --seed {seed}`; "
        "the tutorial is docs/your-log.md.\n"
    )
    return [*out, readme]


__all__ = ["INS_ACCURACY", "NOTE", "example_drive", "sensor_biases", "write_examples"]

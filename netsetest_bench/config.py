"""What one ``netsetest bench`` run measures, and how much (``--quick`` or the full run): :data:`QUICK` and :data:`FULL`.

Each part takes the run's :class:`BenchConfig` and reads the fields it needs; a run writes it into its figures' meta
(``meta.config``)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class BenchConfig:
    """Sizes, step counts, seeds and repetitions of every part (field names: the figures' ``meta.config`` keys)."""

    steps: int
    ref_sched: int
    ref_rule: int
    naive: int
    prev_sched: int
    prev_rule: int
    scaling_steps: int
    scaling_sizes: list[int]
    rt_sizes: list[int]
    rt_steps: int
    profile_nodes: int
    node_budget_nodes: int  # --only node: the profiled ring
    node_budget_reps: int
    campaign_runs: int  # --only campaign: the throughput campaign (bench/campaign.py)
    campaign_reps: int
    campaign_big_runs: int  # a tenth of the 1 000-run campaign (the full part runs it whole)
    scaleout_nodes: int  # --only scaleout: the lockstep ring across one and two namespaces (bench/scaleout.py)
    scaleout_steps: int
    scaleout_reps: int
    startup_reps: int
    launch_reps: int
    flood_steps: int
    flood_rate: int
    crash_steps: int
    soak_steps: int
    flow_steps: int  # --only flow: the paused-collector runs (unpaced paper6)
    flow_pauses_s: tuple[float, ...]
    flow_record_steps: int  # the paper6_lossy runs recording .jsonl.gz and .mcap
    flow_soak_runs: int
    flow_soak_steps: int
    flow_ratio_steps: int | None  # the topology's 80
    view_steps: int  # --only view: real-time paper6 runs with the live view and without (bench/view.py)
    view_pairs: int
    page_reps: int
    cpu_steps: int
    plant_steps: int
    plant_seeds: list[int]
    plant_lap_steps: int
    plant_mb_steps: int
    network_steps: int
    exact_steps: int  # issue 34's record length
    exact_rings: list[tuple[int, float]]  # ring size, CPU budget (s): quick cuts the 24-node search short
    network_seeds: list[int]
    cost_reps: int
    compare_seeds: list[int]
    widths_worst_seeds: list[int]  # --only widths (issue 28's runs)
    widths_car_seeds: list[int]  # held out: the car's mismatch bound is calibrated on seeds 0-9
    widths_lap_steps: int
    sets_seeds: list[int]  # --only widths, issue 44: faults at their bounds, declared bounds true and false
    sets_ring_seeds: list[int]  # issue 44's directed rings
    sets_ring_steps: int
    sets_network_budget_s: float  # CPU seconds for each ring's network limit (k-of-N: the ends past it are relaxed, counted)
    exact_network_seeds: list[int]  # --only exact, issue 44: exact and exact --network on the 12-node ring with two groups
    sets_declared_steps: int
    logs_replay_steps: int  # --only logs: paper6 replayed from a log (30 s of drive)
    logs_reps: int
    logs_train_seeds: list[int]  # synthetic training drives of paper6_car's car
    logs_train_s: float
    logs_held_s: float


QUICK = BenchConfig(
    steps=40,
    ref_sched=24,
    ref_rule=8,
    naive=12,
    prev_sched=24,
    prev_rule=8,
    scaling_steps=20,
    scaling_sizes=[6, 24, 96],
    rt_sizes=[12, 24, 48, 64, 80, 96, 128],
    rt_steps=50,
    profile_nodes=96,
    node_budget_nodes=48,
    node_budget_reps=3,
    campaign_runs=24,
    campaign_reps=2,
    campaign_big_runs=100,
    scaleout_nodes=24,
    scaleout_steps=40,
    scaleout_reps=3,
    startup_reps=3,
    launch_reps=5,
    flood_steps=200,
    flood_rate=30000,
    crash_steps=30,
    soak_steps=2000,
    flow_steps=300,
    flow_pauses_s=(3.0,),
    flow_record_steps=300,
    flow_soak_runs=1,
    flow_soak_steps=300,
    flow_ratio_steps=None,
    view_steps=300,
    view_pairs=3,
    page_reps=5,
    cpu_steps=400,
    plant_steps=80,
    plant_seeds=[10, 11],
    plant_lap_steps=200,
    plant_mb_steps=10,
    network_steps=80,
    exact_steps=80,
    exact_rings=[(12, 600.0), (24, 30.0)],
    network_seeds=[0],
    cost_reps=5,
    compare_seeds=[0, 1],
    widths_worst_seeds=[3, 11],
    widths_car_seeds=[10],
    widths_lap_steps=100,
    sets_seeds=list(range(10)),
    sets_ring_seeds=[0],
    sets_ring_steps=80,
    sets_network_budget_s=900.0,
    exact_network_seeds=[0, 1, 2],
    sets_declared_steps=80,
    logs_replay_steps=300,
    logs_reps=3,
    logs_train_seeds=[1, 2, 3],
    logs_train_s=30.0,
    logs_held_s=30.0,
)

FULL = BenchConfig(
    steps=80,
    ref_sched=80,
    ref_rule=24,
    naive=40,
    prev_sched=80,
    prev_rule=24,
    scaling_steps=40,
    scaling_sizes=[6, 24, 96],
    rt_sizes=[6, 12, 24, 36, 48, 64, 80, 96, 112, 128],
    rt_steps=50,
    profile_nodes=96,
    node_budget_nodes=96,
    node_budget_reps=3,
    campaign_runs=200,
    campaign_reps=2,
    campaign_big_runs=1000,
    scaleout_nodes=48,
    scaleout_steps=80,
    scaleout_reps=3,
    startup_reps=5,
    launch_reps=9,
    flood_steps=400,
    flood_rate=30000,
    crash_steps=60,
    soak_steps=20000,
    flow_steps=1000,
    flow_pauses_s=(3.0, 10.0),
    flow_record_steps=3000,
    flow_soak_runs=5,
    flow_soak_steps=3000,
    flow_ratio_steps=None,
    view_steps=600,
    view_pairs=5,
    page_reps=9,
    cpu_steps=800,
    plant_steps=80,
    plant_seeds=list(range(10, 20)),
    plant_lap_steps=600,
    plant_mb_steps=30,
    network_steps=80,
    exact_steps=80,
    exact_rings=[(12, 600.0), (24, 600.0)],
    network_seeds=[0, 1, 2],
    cost_reps=9,
    compare_seeds=[0, 1, 2],
    widths_worst_seeds=[3, 11],
    widths_car_seeds=[10, 11, 12],
    widths_lap_steps=600,
    sets_seeds=list(range(10)),
    sets_ring_seeds=[0, 1, 2],
    sets_ring_steps=80,
    sets_network_budget_s=3600.0,
    exact_network_seeds=[0, 1, 2],
    sets_declared_steps=80,
    logs_replay_steps=1200,
    logs_reps=5,
    logs_train_seeds=[1, 2, 3, 4, 5],
    logs_train_s=60.0,
    logs_held_s=60.0,
)

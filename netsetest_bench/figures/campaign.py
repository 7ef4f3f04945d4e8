"""The campaign part's figures (bench/campaign.json: ``netsetest bench --only campaign``) as typed data."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

from netsetest_bench.render import typed


@dataclass(frozen=True)
class CampaignRun:
    """One campaign on one engine: its wall and CPU, its runs' own, and (sampled) its workers' resident memory."""

    runs: int
    errors: int
    failed: int
    wall_s: float
    runs_per_s: float | None
    cpu_main_s: float  # the campaign's own process
    run_wall_s: float  # summed over its runs, each in its worker
    run_cpu_s: float
    worker_cpu_s: float | None  # every worker's (or the cluster's every process's) CPU over the campaign
    runs_per_cpu_s: float | None = None  # every process's CPU: what load cannot change
    cores_used: float | None = None  # the share of the cores it got
    memory_mb: list[dict[int, float]] = field(default_factory=list)  # per sample: worker pid → resident MB
    load: str = ""  # the load average at its start


@dataclass(frozen=True)
class Direct:
    """The campaign's runs one after the other in the benchmark's process."""

    runs: int
    wall_s: float
    cpu_s: float
    load: str


@dataclass(frozen=True)
class Arms:
    """Every rep of each arm, in the order they ran within a rep."""

    local_1: list[CampaignRun]
    local_2: list[CampaignRun]
    cluster_2: list[CampaignRun]
    direct: list[Direct]

    def engines(self) -> list[tuple[str, list[CampaignRun]]]:
        """The arms that ran on a campaign engine, by name (``direct`` left out)."""
        return [(f.name, getattr(self, f.name)) for f in fields(self) if f.name != "direct"]


@dataclass(frozen=True)
class Throughput:
    runs: int
    reps: int
    arms: Arms
    cluster_error: str | None
    runs_per_s: dict[str, float | None]  # arm → median
    ratio_2_over_1: float | None
    ratio_cluster_over_local: float | None
    cpu_per_run_s: dict[str, float | None]
    overhead_wall_pct: float | None
    overhead_cpu_pct: float | None
    runs_per_cpu_s: dict[str, float | None] = field(default_factory=dict)
    cpu_ratio_2_over_1: float | None = None
    cpu_ratio_cluster_over_local: float | None = None
    cores_used: dict[str, float | None] = field(default_factory=dict)


@dataclass(frozen=True)
class Resume:
    """``netsetest campaign`` again on the finished results, as a user resumes."""

    wall_s: float
    exit_code: int
    nothing_to_run: bool
    files: int


@dataclass(frozen=True)
class Big:
    """The big campaign on the local pool (the 1 000-run one; ``--quick``: a tenth), its memory and its resume."""

    runs: int
    errors: int
    failed: int
    wall_s: float
    runs_per_s: float | None
    cpu_main_s: float
    run_wall_s: float
    run_cpu_s: float
    worker_cpu_s: float | None
    workers: int
    load_before: str
    load_after: str
    memory_growth_mb: float | None
    memory_first_mb: float | None
    memory_last_mb: float | None
    resume: Resume
    runs_per_cpu_s: float | None = None
    cores_used: float | None = None
    memory_mb: list[dict[int, float]] = field(default_factory=list)


@dataclass(frozen=True)
class Campaign:
    throughput: Throughput
    big: Big
    cpus: int | None


def load(doc: dict, what: str = "the campaign figures") -> Campaign:
    return typed(Campaign, doc, what)

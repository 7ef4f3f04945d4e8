"""Per-node tables of a record for pandas / polars: ``node_<i>.parquet`` or ``node_<i>.csv``.

One row per published step; columns (:data:`COLUMNS`): the step and its time, the estimate, the lower
and upper bound x̂ ∓ √(ρ P_jj) and the true value of β [rad], r [rad/s] and the fault f [rad/s], E, ρ,
contained, continues_contained (the set the node continues from held the truth; empty for older records),
assumptions_ok and the node's status.  CSV needs nothing extra; Parquet needs pyarrow (the
``export`` extra).  A missing value (truth unknown) is empty in CSV and null in Parquet.
"""

from __future__ import annotations

import csv
from pathlib import Path

from netsetest.extras import require
from netsetest.records.record import Record

COMPONENTS = ("beta", "r", "fault")
COLUMNS: tuple[str, ...] = (
    "node",
    "step",
    "t",
    *(f"{c}_{part}" for c in COMPONENTS for part in ("estimate", "lower", "upper", "true")),
    "E",
    "rho",
    "judged",
    "contained",
    "continues_contained",
    "assumptions_ok",
    "status",
)
FORMATS = ("parquet", "csv")


def node_table(rec: Record, node: int) -> dict[str, list]:
    """Column name → values over the node's published steps."""
    tr = rec.nodes[node]
    tau = rec.meta.tau_s
    rows = rec.state_rows(node)
    table: dict[str, list] = {c: [] for c in COLUMNS}
    for n, row in enumerate(rows):
        # the node in every row: read together (pd.read_parquet(dir)), the per-node files stay apart
        extra = {"node": node, "t": row["step"] * tau, "rho": float(tr.rho[n]), "assumptions_ok": bool(tr.assumptions_ok[n])}
        for c in COLUMNS:
            table[c].append(extra[c] if c in extra else row[c])
    return table


def export_record(rec: Record, out_dir: str | Path, fmt: str) -> list[Path]:
    """Write one table per node into ``out_dir`` (created if needed); return the files."""
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {FORMATS}, got {fmt!r}")
    write = _parquet_writer() if fmt == "parquet" else _write_csv
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for i in sorted(rec.nodes):
        path = out / f"node_{i}.{fmt}"
        write(node_table(rec, i), path)
        files.append(path)
    return files


def _write_csv(table: dict[str, list], path: Path) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for row in zip(*(table[c] for c in COLUMNS)):
            w.writerow("" if v is None else repr(v) if isinstance(v, float) else v for v in row)


def _parquet_writer():  # a callable (table, path) -> None
    require("pyarrow", "--parquet")
    import pyarrow as pa
    import pyarrow.parquet as pq

    def write(table: dict[str, list], path: Path) -> None:
        pq.write_table(pa.table({c: table[c] for c in COLUMNS}), path)

    return write

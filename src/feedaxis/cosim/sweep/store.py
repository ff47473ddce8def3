"""The output folder of a sweep and its trial table: finished trials saved as they arrive
(``OUT/.partial/``), the outputs written at the end (``trials.parquet``, ``summary.json``,
``summary.txt``, ``report.html``), and reading them back (:func:`read_sweep`)."""
from __future__ import annotations

import hashlib
import io
import json
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ...errors import InputError, json_safe
from ...output import write_atomically

PARTIAL = ".partial"
TRIALS_FILE = "trials.parquet"
FLUSH_S = 10.0        # finished trials reach OUT/.partial at least this often (s)
DIGEST_CHARS = 16     # hex characters of a part file's SHA-256 kept in its name


class TrialResult(NamedTuple):
    """One trial's outcome: its figures in the scenario's order, its curve (``series``, y
    values) and, when the FMUs refused its values, why (``error``; figures then empty)."""

    trial: int
    figures: tuple
    series: np.ndarray
    error: str | None


@dataclass
class Collected:
    """The finished trials ({trial: TrialResult}) and the axis of their curve."""

    results: dict = field(default_factory=dict)
    series_axis: dict | None = None

    def add(self, results, series_axis):
        for result in results:
            self.results[result.trial] = result
        self.series_axis = self.series_axis or series_axis


class Store:
    """The output folder of a sweep: finished trials saved as they arrive, outputs at the end.

    ``OUT/.partial/plan.json`` holds the plan's identity, ``OUT/.partial/part-N-DIGEST.parquet``
    the finished trials (DIGEST: the start of the file's SHA-256, so a resume finds a part
    damaged anywhere, also where Parquet itself would read changed values); the outputs are ``trials.parquet``, ``summary.json``,
    ``summary.txt`` and ``report.html``.
    """

    def __init__(self, out, identity, resume):
        self.out, self.identity = Path(out), identity
        self.partial = self.out / PARTIAL
        self.pending, self.series_axis, self.flushed_at = [], None, time.monotonic()
        self.parts = 0
        if resume:
            self._check_resumable()
        else:
            if self.out.exists():
                raise InputError("already exists; choose a new folder, or add --resume to "
                                 "finish an interrupted sweep there", path=self.out)
            self.partial.mkdir(parents=True)
            write_atomically(self.partial / "plan.json", json.dumps(identity, indent=1))

    def _check_resumable(self):
        plan_path = self.partial / "plan.json"
        if not plan_path.exists():
            raise InputError("holds no interrupted sweep to resume (no .partial/plan.json)",
                             path=self.out)
        try:
            saved = json.loads(plan_path.read_text(encoding="utf-8"))
        except (ValueError, OSError) as error:
            raise InputError(f"damaged, the plan of the interrupted sweep cannot be read "
                             f"({error}): start the sweep again into a new folder",
                             path=plan_path) from None
        if not isinstance(saved, dict):
            raise InputError("damaged: not the plan of a sweep; start the sweep again into a "
                             "new folder", path=plan_path)
        differ = sorted(k for k in set(saved) | set(self.identity)
                        if saved.get(k) != self.identity.get(k))
        if differ:
            raise InputError(f"holds a different sweep; it differs in {', '.join(differ)}: "
                             "resume with the command that started it", path=self.out)
        self.parts = len(list(self.partial.glob("part-*.parquet")))

    def load(self):
        """The :class:`Collected` trials saved so far."""
        import pyarrow.parquet as pq

        collected = Collected()
        for path in sorted(self.partial.glob("part-*.parquet")):
            try:
                results, axis = _part(pq.read_table(io.BytesIO(_checked_bytes(path))))
            except (OSError, ValueError, KeyError, TypeError) as error:  # pyarrow's: OSError
                raise InputError(f"damaged ({type(error).__name__}: {error}); remove it and "
                                 "run the same command with --resume again to rerun its "
                                 "trials", path=path) from None
            collected.add(results, axis)
        self.series_axis = collected.series_axis
        return collected

    def add(self, results, series_axis):
        """Keep ``results``; save them when the last save is :data:`FLUSH_S` old."""
        self.pending += results
        self.series_axis = self.series_axis or series_axis
        if time.monotonic() - self.flushed_at >= FLUSH_S:
            self.flush()

    def flush(self):
        """Save the pending results as one more part file."""
        import pyarrow as pa

        self.flushed_at = time.monotonic()
        if not self.pending:
            return
        table = pa.table({
            "trial": pa.array([r.trial for r in self.pending], pa.int64()),
            "figure_names": pa.array([[n for n, _ in r.figures] for r in self.pending],
                                     pa.list_(pa.string())),
            "figure_values": pa.array([[v for _, v in r.figures] for r in self.pending],
                                      pa.list_(pa.float64())),
            "series": pa.array([r.series.tolist() for r in self.pending],
                               pa.list_(pa.float64())),
            "error": pa.array([r.error for r in self.pending], pa.string())})
        if self.series_axis:
            table = table.replace_schema_metadata(
                {"feedaxis.series": json.dumps(self.series_axis)})
        self.parts += 1
        data = parquet_bytes(table)
        write_atomically(self.partial / f"part-{self.parts:06d}-{_digest(data)}.parquet", data)
        self.pending = []

    def complete(self):
        """Remove the saved parts once the outputs hold every trial."""
        shutil.rmtree(self.partial, ignore_errors=True)


def _digest(data):
    """The start of the SHA-256 of ``data`` (bytes) that a part file's name carries."""
    return hashlib.sha256(data).hexdigest()[:DIGEST_CHARS]


def _checked_bytes(path):
    """The bytes of the part file ``path``; ValueError where they no longer match the
    digest in its name."""
    data = path.read_bytes()
    named = path.stem.rsplit("-", 1)[-1]
    if named != _digest(data):
        raise ValueError(f"its content no longer matches the digest {named} in its name")
    return data


def _part(table):
    """([TrialResult], series axis or None) of a saved part file's table."""
    axis = (table.schema.metadata or {}).get(b"feedaxis.series")
    results = [TrialResult(int(row["trial"]), tuple(zip(row["figure_names"],
                                                        row["figure_values"])),
                           np.array(row["series"], dtype=float), row["error"])
               for row in table.to_pylist()]
    return results, axis and json.loads(axis)


def parquet_bytes(table):
    """``table`` as Parquet file bytes (one row group, zstd)."""
    import pyarrow.parquet as pq

    buffer = io.BytesIO()
    pq.write_table(table, buffer, compression="zstd", row_group_size=max(1, table.num_rows))
    return buffer.getvalue()


def finish(plan, identity, collected, store):
    """The trial table of the ``collected`` trials; with a store, also its files (the
    parts removed once every trial is in)."""
    from .summary import summarise, summary_lines

    table = trial_table(plan, identity, collected.results, collected.series_axis)
    if store is None:
        return table
    summary = summarise(table)
    write_atomically(store.out / TRIALS_FILE, parquet_bytes(table))
    write_atomically(store.out / "summary.json",
                     json.dumps(json_safe(summary), indent=1, allow_nan=False))
    write_atomically(store.out / "summary.txt", summary_lines(summary) + "\n")
    from ...report.sweep import write_sweep_report

    write_sweep_report(summary, table, store.out / "report.html")
    if table.num_rows == plan.trials:
        store.complete()
    return table


def trial_table(plan, identity, results, series_axis=None):
    """The finished trials as one :class:`pyarrow.Table`, sorted by trial (see
    :func:`sweep`); the plan and the series' axis in its metadata."""
    import pyarrow as pa

    trials = sorted(results)
    ordered = [results[k] for k in trials]
    names = _figure_names(ordered)
    columns = {"trial": pa.array(trials, pa.int64())}
    inputs = [plan.inputs(k) for k in trials]
    for name in plan.input_names:
        columns[name] = pa.array([values[name] for values, _, _ in inputs], pa.float64())
    if plan.draws is not None:
        columns["redraws"] = pa.array([redraws for _, _, redraws in inputs], pa.int64())
    for name in names:
        columns[name] = pa.array([dict(r.figures).get(name) for r in ordered], pa.float64())
    columns["series"] = pa.array([r.series.tolist() for r in ordered], pa.list_(pa.float64()))
    columns["error"] = pa.array([r.error for r in ordered], pa.string())
    metadata = {"plan": identity, "inputs": list(plan.input_names), "figures": names,
                "series": series_axis}
    table = pa.table(columns)
    return table.replace_schema_metadata(
        {"feedaxis.sweep": json.dumps(json_safe(metadata), allow_nan=False)})


def _figure_names(results):
    """Figure names in the scenario's order (that of the first trial with figures), then
    any other in alphabetical order."""
    first = next((r.figures for r in results if r.figures), ())
    names = [n for n, _ in first]
    others = sorted({n for r in results for n, _ in r.figures} - set(names))
    return names + others


def read_sweep(out):
    """The trial table of a sweep folder (``OUT/trials.parquet``)."""
    import pyarrow.parquet as pq

    path = Path(out) / TRIALS_FILE
    if not path.exists():
        raise InputError("no trials.parquet: not a sweep folder", path=out)
    return pq.read_table(path)


def sweep_metadata(table):
    """The ``feedaxis.sweep`` metadata of a trial table as a dict."""
    return json.loads(table.schema.metadata[b"feedaxis.sweep"])

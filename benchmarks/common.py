"""What every benchmark shares: the ``--smoke`` run for CI and the machine it ran on.

Every benchmark script has ``main(argv=None)``; ``--smoke`` runs it at its smallest sizes
(CI runs each so, ``tests/docs/test_benchmarks.py``: it must finish, not meet a time).
``python benchmarks/speed_page.py`` runs them all at full size and writes docs/speed.md from
their output, with the machine and the date.
"""
from __future__ import annotations

import contextlib
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from typing import NamedTuple


def arguments(parser, argv, **smoke):
    """Parse ``argv`` with ``--smoke`` added: given, the ``smoke`` values replace the
    parsed ones (the smallest sizes that still run every part of the benchmark)."""
    parser.add_argument("--smoke", action="store_true",
                        help="the smallest run, for CI: it must finish, not meet a time")
    args = parser.parse_args(argv)
    if args.smoke:
        for name, value in smoke.items():
            setattr(args, name, value)
    return args


def describe(values, unit="s"):
    """Median and range of repeated timings, with their count."""
    return (f"median {statistics.median(values):.3f} {unit} "
            f"(range {min(values):.3f}-{max(values):.3f}, n = {len(values)})")


def clopper_pearson(count, trials, level=0.95):
    """Two-sided interval of a binomial rate."""
    from scipy import stats

    tail = (1 - level) / 2
    low = stats.beta.ppf(tail, count, trials - count + 1) if count else 0.0
    high = stats.beta.ppf(1 - tail, count + 1, trials - count) if count < trials else 1.0
    return low, high


def rate(count, trials):
    """``count`` of ``trials`` as a rate with its 95 % Clopper-Pearson interval."""
    low, high = clopper_pearson(count, trials)
    return f"{count:3d}/{trials} ({100 * count / trials:5.2f} %, 95 % {100 * low:.2f}-{100 * high:.2f})"
class Command(NamedTuple):
    """What one command cost and printed: wall and CPU seconds (its own and its reaped
    children's, as wait4 gives them: user + system, and the system's part), peak resident
    memory (MB), its output."""

    wall_s: float
    cpu_s: float
    peak_mb: float
    stdout: str
    stderr: str
    system_s: float


def run_command(command, env=None):
    """:class:`Command` of ``command`` (a list) run to its end (in the environment ``env``,
    else this one's); a failure raises."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        process = subprocess.Popen(command, stdout=out, stderr=err, env=env)
        _, status, usage = os.wait4(process.pid, 0)
        wall_s = time.perf_counter() - start
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(), err.read().decode()
    if os.waitstatus_to_exitcode(status):
        raise RuntimeError(f"{' '.join(command[2:5])} failed: {stderr.strip().splitlines()[-1:]}")
    return Command(wall_s, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, stdout,
                   stderr, usage.ru_stime)


def machine():
    """One line: CPU model, cores, memory, load, Python and NumPy, the date (UTC)."""
    import numpy

    model = next((line.split(":", 1)[1].strip() for line in _lines("/proc/cpuinfo")
                  if line.startswith("model name")), platform.processor() or "unknown CPU")
    memory_kb = next((int(line.split()[1]) for line in _lines("/proc/meminfo")
                      if line.startswith("MemTotal")), 0)
    load = ", ".join(f"{value:.1f}" for value in os.getloadavg())
    return (f"{model}, {os.cpu_count()} cores, {memory_kb / 2**20:.0f} GiB, load average "
            f"{load}; Python {sys.version.split()[0]}, NumPy {numpy.__version__}; "
            f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")


def _lines(path):
    try:
        with open(path, encoding="utf-8") as stream:
            return stream.read().splitlines()
    except OSError:
        return []


@contextlib.contextmanager
def slow_tracking_paths():
    """The tracking fit's paths before its sensitivities, for a baseline timed in the same
    run: forward differences for every Jacobian (``Measurement.sensitivities`` off) and
    every fit of a diagnosis made anew (its refitter's memo bypassed)."""
    from feedaxis.diagnose import Refitter
    from feedaxis.fit import fit
    from feedaxis.measurement import Measurement

    saved = Measurement.sensitivities, Refitter.fit
    Measurement.sensitivities = False
    Refitter.fit = lambda self, model: fit(model, self.measurement)
    try:
        yield
    finally:
        Measurement.sensitivities, Refitter.fit = saved


def side_by_side(jobs, repeats):
    """{label: ([wall s], [CPU s], last result)} of ``jobs`` ({label: (context, function)})
    run in turn ``repeats`` times, interleaved so that a change of the machine's load falls
    on every job alike."""
    timings = {label: ([], [], None) for label in jobs}
    for _ in range(repeats):
        for label, (context, function) in jobs.items():
            with context():
                wall, cpu = time.perf_counter(), time.process_time()
                result = function()
                walls, cpus, _ = timings[label]
                walls.append(time.perf_counter() - wall)
                cpus.append(time.process_time() - cpu)
            timings[label] = (walls, cpus, result)
    return timings


def ratio_lines(timings, new, old):
    """Lines of each job's wall and CPU medians with their ranges, then old / new."""
    lines = [f"  {label:44s} wall {describe(walls)}; CPU {describe(cpus)}"
             for label, (walls, cpus, _) in timings.items()]
    old_cpu, new_cpu = (statistics.median(timings[label][1]) for label in (old, new))
    old_wall, new_wall = (statistics.median(timings[label][0]) for label in (old, new))
    lines.append(f"  ratio {old} / {new}: CPU {old_cpu / new_cpu:.2f}x, wall "
                 f"{old_wall / new_wall:.2f}x")
    return lines

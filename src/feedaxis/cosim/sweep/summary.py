"""What a sweep's trials say together: quantiles, sensitivities and prediction bands.

- Quantiles of each figure over the trials that ran (NumPy's default, linear between order
  statistics), with mean and sample standard deviation.
- Sensitivities of each figure to each varied input: the standardised regression
  coefficient (SRC = b·s_x/s_y of the least-squares fit of the figure on all inputs; the
  SRCs' squares add up to R² when the inputs are uncorrelated, and R² says how much of the
  spread a linear model explains) and Spearman's rank correlation with its p-value (for
  monotone, not linear, dependence).
- Prediction bands of the scenario's curve: at each point the 2.5, 50 and 97.5 % quantiles
  of the trials, and their mean and standard deviation.
"""
from __future__ import annotations

import json

import numpy as np

QUANTILES = (0.025, 0.05, 0.25, 0.5, 0.75, 0.95, 0.975)
BAND = (0.025, 0.5, 0.975)
SHOWN_FAILURES = 10


def summarise(table):
    """The summary of a trial table (:func:`feedaxis.cosim.sweep.trial_table`) as JSON-ready
    data."""
    metadata = json.loads(table.schema.metadata[b"feedaxis.sweep"])
    plan = metadata["plan"]
    error = table.column("error").to_pylist()
    ok = np.array([e is None for e in error], dtype=bool)
    inputs = {name: table.column(name).to_numpy(zero_copy_only=False)[ok]
              for name in metadata["inputs"]}
    figures = {name: table.column(name).to_numpy(zero_copy_only=False).astype(float)[ok]
               for name in metadata["figures"]}
    summary = {
        "scenario": plan["scenario"], "planned_trials": plan["trials"],
        "finished_trials": table.num_rows, "failed_trials": int(np.sum(~ok)),
        "complete": table.num_rows == plan["trials"], "seed": plan["seed"],
        "vary": plan["vary"], "from_model": plan["from_model"], "held": plan["held"],
        "figures": {name: _distribution(values) for name, values in figures.items()},
        "sensitivities": {name: sensitivities(inputs, values)
                          for name, values in figures.items()},
        "bands": _bands(table, ok, metadata["series"]),
        "failures": [{"trial": int(t), "error": e} for t, e in
                     zip(table.column("trial").to_pylist(), error) if e][:SHOWN_FAILURES],
    }
    if "redraws" in table.column_names:
        summary["redraws"] = int(np.sum(table.column("redraws").to_numpy()))
    return summary


def _distribution(values):
    values = values[np.isfinite(values)]
    if values.size == 0:
        return {"n": 0}
    return {"n": int(values.size), "mean": float(np.mean(values)),
            "sd": float(np.std(values, ddof=1)) if values.size > 1 else None,
            "min": float(np.min(values)), "max": float(np.max(values)),
            "quantiles": {f"{q:g}": float(np.quantile(values, q)) for q in QUANTILES}}


def sensitivities(inputs, figure):
    """{"r2": R², "inputs": {name: {"src", "spearman", "p_value"}}} of ``figure`` on the
    ``inputs`` ({name: values}) that vary; empty when too few trials."""
    finite = np.isfinite(figure)
    varying = {n: v[finite] for n, v in inputs.items() if v[finite].size and np.ptp(v[finite]) > 0}
    y = figure[finite]
    if not varying or y.size < len(varying) + 2 or np.ptp(y) == 0:
        return {}
    from scipy.stats import spearmanr  # a second's import, only where it is used

    x = np.column_stack(list(varying.values()))
    design = np.column_stack([np.ones(y.size), x])
    coefficients, *_ = np.linalg.lstsq(design, y, rcond=None)
    residual = y - design @ coefficients
    r2 = 1.0 - float(residual @ residual) / float(np.sum((y - y.mean()) ** 2))
    result = {}
    for i, (name, values) in enumerate(varying.items()):
        rho, p_value = spearmanr(values, y)
        result[name] = {"src": float(coefficients[i + 1] * np.std(values) / np.std(y)),
                        "spearman": float(rho), "p_value": float(p_value)}
    return {"r2": r2, "inputs": result}


def _bands(table, ok, axis):
    """Quantiles, mean and sd of the curve at each of its points over the trials that ran."""
    rows = [np.asarray(s, dtype=float) for s, good in
            zip(table.column("series").to_pylist(), ok) if good]
    if axis is None or not rows or len({r.size for r in rows}) != 1:
        return None
    y = np.vstack(rows)
    band = {"x_name": axis["x_name"], "x": axis["x"], "y_name": axis["y_name"],
            "group": axis["group"], "trials": int(y.shape[0]),
            "mean": np.mean(y, axis=0).tolist(),
            "sd": np.std(y, axis=0, ddof=1).tolist() if y.shape[0] > 1 else None}
    for q in BAND:
        band[f"q{q:g}"] = np.quantile(y, q, axis=0).tolist()
    return band


def summary_lines(summary):
    """The summary as text."""
    lines = [f"sweep of {summary['scenario']}: {summary['finished_trials']} of "
             f"{summary['planned_trials']} trials"
             + ("" if summary["complete"] else " (interrupted: --resume runs the rest)")
             + (f", {summary['failed_trials']} refused by the FMUs"
                if summary["failed_trials"] else "")
             + f"; seed {summary['seed']}"]
    lines += [f"  vary {text}" for text in summary["vary"]]
    if summary["from_model"]:
        lines.append(f"  parameters of {summary['from_model']} drawn from its fit's covariance"
                     + (f" ({summary['redraws']} draws outside the effects' bounds drawn "
                        "again)" if summary.get("redraws") else ""))
    lines += [f"  held at the fitted value (undetermined): {key} ({why})"
              for key, why in summary["held"].items()]
    lines.append("figure: mean, sd, quantiles 2.5 % | 50 % | 97.5 %")
    for name, d in summary["figures"].items():
        if d["n"] == 0:
            lines.append(f"  {name}: no finite value")
            continue
        q = d["quantiles"]
        sd = "" if d["sd"] is None else f" ± {d['sd']:.4g}"
        lines.append(f"  {name}: {d['mean']:.6g}{sd}; {q['0.025']:.6g} | {q['0.5']:.6g} | "
                     f"{q['0.975']:.6g}")
    for name, s in summary["sensitivities"].items():
        if s:
            ranked = sorted(s["inputs"].items(), key=lambda item: -abs(item[1]["src"]))
            lines.append(f"  sensitivity of {name} (linear R² {s['r2']:.3f}): " + ", ".join(
                f"{n} SRC {v['src']:+.3f} (Spearman {v['spearman']:+.3f})" for n, v in ranked))
    lines += [f"  trial {f['trial']} refused: {f['error']}" for f in summary["failures"]]
    return "\n".join(lines)

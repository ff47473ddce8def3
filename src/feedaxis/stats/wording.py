"""How a statistic is written for people, the same in the terminal, the report and the
evidence of every test (no import: the CLI's text uses it before anything numerical loads)."""
from __future__ import annotations

SMALLEST_P = 1e-300  # a smaller p-value is written as this bound (near the doubles' floor)


def p_text(p_value):
    """A p-value as every output of feedaxis writes it: ``p = 2.1e-05``, ``p < 1e-300``
    (never ``p 0``)."""
    return f"p < {SMALLEST_P:g}" if p_value < SMALLEST_P else f"p = {p_value:.2g}"

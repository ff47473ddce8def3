"""``python -m feedaxis``: the console script."""
from .console import run

run()

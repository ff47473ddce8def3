"""The HTML report: plots (matplotlib, PNG) kept apart from the calculations."""
from .page import error_ladder, write_report

__all__ = ["error_ladder", "write_report"]

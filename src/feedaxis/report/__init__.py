"""The HTML report: plots (matplotlib, PNG) and a page formatting an ``Analysis``."""
from .page import write_report

__all__ = ["write_report"]

"""feedaxis: digital twin of a ball-screw feed axis (FMI 2.0 FMUs over one physics core)."""
__version__ = "0.2.0"


def __getattr__(name):
    """``feedaxis.sweep``: :func:`feedaxis.cosim.sweep.sweep`, imported on first use (Dask
    and pyarrow load in seconds; ``import feedaxis`` stays instant)."""
    if name == "sweep":
        from .cosim.sweep import sweep

        return sweep
    raise AttributeError(f"module 'feedaxis' has no attribute {name!r}")

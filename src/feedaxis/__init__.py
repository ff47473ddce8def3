"""feedaxis: digital twin of a ball-screw feed axis (FMI 2.0 FMUs over one physics core)."""
__version__ = "0.2.0"

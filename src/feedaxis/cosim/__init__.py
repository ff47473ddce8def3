"""Running the feedaxis FMUs through fmpy."""

"""FMU sources: one folder per FMU (slave script, README, cross-check files) and common/."""

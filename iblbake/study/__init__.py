"""Studies over many frames: sweeps, contact sheets, the accuracy study (next issues)."""

"""Studies made of many runs: mismatch sweeps (`study` file, `cases`, `executor`, `summary`, `sweep`),
margins, stability, fidelity and the findings."""

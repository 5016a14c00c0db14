"""Studies made of many runs: mismatch sweeps (`study` file and case expansion, `executor`, `results`,
`summary`, `sweep`) and the plant-fidelity study (`fidelity`)."""

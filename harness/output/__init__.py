"""Outputs of a run, consumers of an in-memory `Trajectory`: the Rerun recording (`record`) and the
matplotlib figures (`plots`)."""

"""`python -m harness.cli` = `teleop` (`harness.cli.entry`: `main()` and a fast exit)."""

from harness.cli import entry

entry()

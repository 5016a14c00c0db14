"""`python -m harness.cli` = `teleop`."""

import sys

from harness.cli import main

sys.exit(main())

#!/usr/bin/env python3
"""Start the simulated cell (same as `defgg-bringup`; see its --help)."""
import sys

from defgg_ros.bringup.cli import main

if __name__ == "__main__":
    sys.exit(main())

"""Entry point: ``python -m tools.detector COMMAND ...`` (see cli.py)."""

from common.lifecycle import run_main
from tools.detector.cli import main

run_main(main, "detector")

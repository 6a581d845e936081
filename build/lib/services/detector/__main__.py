"""Entry point: ``python -m services.detector COMMAND ...`` (see cli.py)."""

from common.lifecycle import run_main
from services.detector.cli import main

run_main(main, "detector")

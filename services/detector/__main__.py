"""Entry point: ``python -m services.detector COMMAND ...`` (see cli.py)."""

from services.detector.cli import main

raise SystemExit(main())

"""python -m services.detector [serve] [--config FILE] [--backend NAME] [--model FILE]

serve (the default) runs the detector service on the Zenoh bus: newest frame in, detections out.
It only loads the models ``zstack prepare`` made: a missing one stops it with one line naming
it and that command. What people run on photos, videos and models (detect, benchmark, prepare,
fetch-model, fast-profile, export) is ``python -m tools.detector`` (``zstack detect`` ...).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

from common.cli import Command, add_config, service_main
from common.errors import ConfigError, StackError
from common.lifecycle import exit_code, run_main, setup_logging, stop_event
from stack.config_file import load_config


def _serve_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)
    p.add_argument(
        "--backend", help="override detector.backend: onnx, tensorrt, cuda, openvino or auto"
    )
    p.add_argument("--model", help="override detector.model")
    p.add_argument(
        "--worker",
        help="this worker's name, one of detector.workers': detector, detector_2 ... or "
        "detector_<worker_id>, detector_<worker_id>_2 ... (default: the first; docs/detector.md, "
        "'A pool of workers')",
    )


def serve(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    overrides = {k: v for k, v in (("backend", args.backend), ("model", args.model)) if v}
    if overrides:
        config = dataclasses.replace(
            config, detector=dataclasses.replace(config.detector, **overrides)
        )
    worker = args.worker or config.detector_services[0]
    if worker not in config.detector_services:
        known = list(config.detector_services)
        raise ConfigError(
            f"no detector worker {worker!r} (detector.workers, detector.worker_id); known: {known}"
        )
    setup_logging(worker)
    from perception import PREPARE_COMMAND, NotPrepared
    from services.detector.service import run

    try:
        return run(config, stop, worker)
    except NotPrepared as exc:  # one line naming what to run for this very config
        words = [PREPARE_COMMAND, *(["--config", config.path] if config.path else [])]
        words += [f"--{k}={v}" for k, v in overrides.items()]
        raise exc.to_run(" ".join(words)) from exc


COMMANDS = [Command("serve", "run the detector service on the Zenoh bus", _serve_arguments, serve)]


def main() -> int:
    """The command's exit code; a StackError is one line, ``error: ...``, as the detector's
    commands write it (the supervisor names the service: ``detector: error: ...``)."""
    try:
        return service_main("python -m services.detector", __doc__ or "", COMMANDS)
    except StackError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exit_code(exc)


if __name__ == "__main__":
    run_main(main, "detector", skip_finalizing=True)

"""``python -m tools.report``: a run of the stack as report.md plus PNG plots.

Either records a new session (starts the stack with ``--config`` for ``--duration`` seconds,
see :mod:`tools.report.session`) or reads a saved one (``--from session.json``). Detector
benchmarks of several backends (``python -m tools.detector benchmark --json`` output, one
object per line or per file) add a backend comparison. The output folder gets ``report.md``,
the plots, and ``session.json`` so the report can be regenerated without running anything.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from common.contracts import BackendBenchmark, Session
from common.errors import ConfigError
from common.lifecycle import print_progress
from tools.report.plots import SEGMENTS, benchmark_label, segment_means
from tools.report.session import check_session

DEFAULT_DURATION_S = 30.0
DEFAULT_STARTUP_TIMEOUT_S = 180.0
#: Stage name, and what it covers, in the order a frame goes through them.
STAGE_ROWS = (
    ("capture_to_detector", "capture \u2192 the frame reached the detector"),
    ("preprocess", "letterbox, normalise"),
    ("inference", "the model"),
    ("postprocess", "decode, NMS"),
    ("capture_to_detections", "capture \u2192 detections sent"),
    ("detections_to_command", "detections \u2192 first command"),
    ("end_to_end", "capture \u2192 first command"),
)


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: not valid JSON ({exc})") from exc


def read_session(path: Path) -> Session:
    """A saved session.json, checked; ConfigError naming the file if it is not one."""
    return check_session(_read_json(path), str(path))


def load_benchmarks(paths: Sequence[str]) -> list[BackendBenchmark]:
    """Detector benchmark results: each file holds one JSON object, or one per line. An object
    from a side-by-side run (``benchmark --backend a --backend b``) gives one per backend."""
    out: list[BackendBenchmark] = []
    for raw in paths:
        path = Path(raw)
        try:
            text = path.read_text(encoding="utf-8").strip()
        except OSError as exc:
            raise ConfigError(f"{path}: cannot read ({exc.strerror or exc})") from exc
        try:
            items = (
                [json.loads(text)]
                if text.startswith("{") and "\n{" not in text
                else [json.loads(line) for line in text.splitlines() if line.strip()]
            )
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{path}: not benchmark JSON ({exc})") from exc
        for item in items:
            side_by_side = item.get("backends") if isinstance(item, dict) else None
            for one in side_by_side.values() if isinstance(side_by_side, dict) else [item]:
                if not isinstance(one, dict) or not isinstance(one.get("p50_ms"), dict):
                    raise ConfigError(f"{path}: not `tools.detector benchmark --json` output")
                if isinstance(item.get("machine"), dict):
                    one = {"machine": item["machine"], **one}  # where it ran, for the report
                out.append(cast(BackendBenchmark, one))
    return out


def _ms(v: float) -> str:
    return f"{v:.0f}" if v >= 10 else f"{v:.1f}"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(row) + " |" for row in rows]


def _summary_rows(session: Session) -> list[list[str]]:
    s, tl = session["summary"], session["summary"]["timeline"]
    period = float(tl.get("period_s", 1.0))
    # Detected, offered and dropped over one span, the timeline's: the totals since start
    # also count the warm-up before the detector's first counters and would not compare.
    detected = sum(tl.get("fps", ())) * period
    offered = sum(tl.get("offered_fps", ())) * period
    dropped = sum(tl.get("dropped", ()))
    e2e = s["latency_ms"].get("end_to_end", {})
    classes = ", ".join(f"{k} {v}" for k, v in list(s.get("class_counts", {}).items())[:8])
    e2e_text = (
        f"p50 {_ms(e2e.get('p50', 0))} ms, p95 {_ms(e2e.get('p95', 0))} ms, "
        f"p99 {_ms(e2e.get('p99', 0))} ms ({e2e.get('count', 0):.0f} commands)"
    )
    return [
        ["frames offered to the detector", f"{offered:.0f}"],
        ["frames detected", f"{detected:.0f} ({s['fps']:.2f} FPS)"],
        ["dropped by the detector", f"{dropped:.0f} (drop rate {s.get('drop_rate', 0.0):.1%})"],
        ["detections per frame", f"{s['detections_per_frame']:.2f}"],
        ["end to end, capture \u2192 command", e2e_text],
        ["classes seen (boxes)", classes or "none"],
    ]


def _machine_rows(m: Mapping[str, Any]) -> list[list[str]]:
    providers = ", ".join(m.get("onnxruntime_providers", []))
    return [
        ["CPU", f"{m.get('cpu_model')} ({m.get('cpu_count')} logical cores)"],
        ["RAM", f"{m.get('ram_gib')} GiB"],
        ["OS", str(m.get("os"))],
        ["Python", str(m.get("python"))],
        ["onnxruntime", f"{m.get('onnxruntime')} ({providers})"],
        ["GPU", "; ".join(m.get("gpus") or []) or "none"],
    ]


def render_markdown(session: Session, plots: Mapping[str, Path]) -> str:
    """report.md: summary, per-stage latency, plots, setup and machine."""
    s, cfg = session["summary"], session.get("config", {})
    det = session.get("detector", {})
    lines = [
        "# Stack report",
        "",
        f"Recorded {session.get('created', '?')} for {session['duration_s']:.0f} s, after every "
        "service was ready (model loading and warm-up are not in these figures). "
        f"Detector: `{det.get('model', '?')}` on `{det.get('backend', '?')}`.",
        "",
        "## Summary",
        "",
        *_table(["", ""], _summary_rows(session)),
        "",
        "## Latency per stage (ms)",
        "",
    ]
    rows = []
    for stage, what in STAGE_ROWS:
        p = s["latency_ms"].get(stage, {})
        figures = [_ms(p.get(q, 0.0)) for q in ("p50", "p95", "p99", "mean")]
        rows.append([f"`{stage}`", what, *figures, f"{p.get('count', 0):.0f}"])
    lines += _table(["stage", "covers", "p50", "p95", "p99", "mean", "samples"], rows)
    lines += [
        "",
        "The samples are the frames whose detections the report received while it recorded; "
        "the summary's frame counts are whole seconds of the per-second timeline, so the two "
        "can differ by the frames of a part second at either end.",
    ]
    means = segment_means(s["latency_ms"])
    parts = ", ".join(f"{seg} {_ms(means[seg])}" for seg, _ in SEGMENTS)
    lines += ["", f"The mean frame, in parts that add up (ms): {parts}."]
    lines += [f"`wait` is time in the detector outside its timed stages: {SEGMENTS[1][1]}."]
    captions = {
        "latency_histogram": "Latency per frame",
        "stage_breakdown": "Where the time goes",
        "fps_over_time": "Throughput over time",
        "backend_comparison": "Backends compared",
    }
    for key, caption in captions.items():
        if key in plots:
            lines += ["", f"![{caption}]({plots[key].name})"]
    benchmarks = session.get("benchmarks") or []
    if benchmarks:
        lines += ["", "## Backends (detector benchmark, p50 ms per image)", ""]
        stages = ("preprocess", "inference", "postprocess", "total")
        rows = []
        for b in benchmarks:
            p50 = [_ms(b["p50_ms"].get(k, 0.0)) for k in stages]
            agree = b.get("agreement", {})
            agreement = f"{agree['map50_95']:.3f}" if "map50_95" in agree else "-"
            p95 = _ms(b.get("p95_ms", {}).get("total", 0.0))
            m = b.get("machine") or {}
            where = f"{m.get('cpu_model', '?')}, {m.get('cpu_count', '?')} cores" if m else "-"
            rows.append([benchmark_label(b), *p50, p95, agreement, where])
        lines += [
            "Benchmarks can come from another machine than the run above: the last column "
            "says where each one ran.",
            "",
        ]
        lines += _table(
            ["backend", *stages, "total p95", "mAP50-95 vs onnx fp32", "measured on"], rows
        )
    lines += ["", "## Setup", ""]
    lines += _table(["setting", "value"], [[f"`{k}`", f"`{v}`"] for k, v in cfg.items()])
    lines += ["", "## Machine", ""]
    lines += _table(["", ""], _machine_rows(session.get("machine", {})))
    lines += [
        "",
        "Latency is measured from each frame's capture stamp, on one host's clock. Regenerate "
        "this report from `session.json` with "
        "`python -m tools.report --from session.json --out DIR`.",
        "",
    ]
    return "\n".join(lines)


def write_report(session: Session, out: Path) -> list[Path]:
    """Write the plots, report.md and session.json into ``out``; return what was written."""
    from tools.report import plots as draw  # matplotlib: only when a report is made

    out.mkdir(parents=True, exist_ok=True)
    s, samples = session["summary"], session["latency_samples_ms"]
    made = {
        "latency_histogram": draw.latency_histogram(samples, out / "latency_histogram.png"),
        "stage_breakdown": draw.stage_breakdown(
            s["latency_ms"], samples, out / "stage_breakdown.png"
        ),
        "fps_over_time": draw.fps_over_time(s["timeline"], out / "fps_over_time.png"),
    }
    benchmarks = session.get("benchmarks") or []
    if len(benchmarks) > 1:
        made["backend_comparison"] = draw.backend_comparison(
            benchmarks, out / "backend_comparison.png"
        )
    report = out / "report.md"
    report.write_text(render_markdown(session, made), encoding="utf-8")
    saved = out / "session.json"
    saved.write_text(json.dumps(session), encoding="utf-8")
    return [report, *made.values(), saved]


@dataclass(frozen=True, slots=True, kw_only=True)
class ReportOptions:
    """What ``report`` was asked: the output folder; either a run to record (its stack config,
    seconds, and how long the stack may take to start) or a saved session to read
    (``from_file``); and detector benchmark files to compare."""

    out: str
    config: str | None = None
    duration_s: float | None = None  # None: DEFAULT_DURATION_S
    from_file: str | None = None
    benchmarks: tuple[str, ...] = ()
    startup_timeout_s: float = DEFAULT_STARTUP_TIMEOUT_S


def run(options: ReportOptions, stop: threading.Event) -> int:
    """The ``report`` command."""
    out = Path(options.out)
    if options.from_file:
        if options.config or options.duration_s is not None:
            raise ConfigError("--from reads a saved session; --config and --duration are for a run")
        session = read_session(Path(options.from_file))
    else:
        from tools.report.session import record  # zenoh: only when recording

        out.mkdir(parents=True, exist_ok=True)
        duration = DEFAULT_DURATION_S if options.duration_s is None else options.duration_s
        log = out / "supervisor.log"
        session = record(
            options.config, duration, log, stop, print_progress, options.startup_timeout_s
        )
    if options.benchmarks:
        session["benchmarks"] = load_benchmarks(options.benchmarks)
    for path in write_report(session, out):
        print(path)
    return 0

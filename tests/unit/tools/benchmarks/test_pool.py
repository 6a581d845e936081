"""The pool benchmark's pure parts: ratios, the hand-over summary, the two assignment rules
compared, the odds over random names, the configs it writes, the text and the options."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

import pytest

from common.announce import to_chunk
from common.errors import StackError
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import WorkerAnnouncement
from services.detector.pool import assign, rank
from stack.config_file import load_config
from tools.benchmarks.__main__ import _counts
from tools.benchmarks.pool import (
    HEAVY,
    LIGHT,
    POOL,
    UNEVEN,
    Kill,
    PoolOptions,
    Result,
    compare_rules,
    handover_summary,
    heavy_together_odds,
    plain_rendezvous,
    pool_ratios,
    render_handover,
    render_results,
    render_rules,
    to_json,
)
from tools.benchmarks.pool_capacity import announced
from tools.benchmarks.stacks import CameraLoad, split, stack_config


def _result(n: int, workers: int, fps: list[float], p50: float, label: str = "even") -> Result:
    names = [f"c{i}" for i in range(n)]
    half = names[: n // 2] if workers == 2 else names
    served = {"detector": half} | ({"detector_2": names[n // 2 :]} if workers == 2 else {})
    return Result(
        label=label,
        n=n,
        workers=workers,
        seconds=10.0,
        fps=dict(zip(names, fps, strict=True)),
        asked_hz=dict.fromkeys(names, 10.0),
        p50_ms=dict.fromkeys(names, p50),
        p95_ms=dict.fromkeys(names, 2 * p50),
        served=served,
        loads={w: len(c) / n for w, c in served.items()},
        duplicates=0,
    )


def test_ratios_put_two_workers_over_one_for_each_camera_count() -> None:
    results = [
        _result(4, 1, [1.0, 1.0, 1.0, 2.0], p50=400),
        _result(4, 2, [1.5, 1.5, 1.5, 1.5], p50=300),
        _result(8, 1, [0.5] * 8, p50=900),
        _result(4, 2, [2.0, 2.0, 0.5, 0.5], p50=100, label="uneven"),  # not an even condition
    ]
    (row,) = pool_ratios(results)  # N=8 has no 2-worker run: no row
    assert row["n"] == 4
    assert row["fps"] == pytest.approx(6.0 / 5.0)
    assert row["p50"] == pytest.approx(0.75)
    assert row["p95"] == pytest.approx(0.75)
    assert row["fairness"] == pytest.approx(1.0 / 0.5)
    assert results[0].fairness == 0.5
    assert results[0].total_fps == 5.0


def test_handover_summary_covers_every_camera_of_every_kill() -> None:
    kills = [
        Kill(victim="detector_2", handover_s={"a": 0.2, "b": 0.4}, rejoin_s=20.0),
        Kill(victim="detector", handover_s={"c": 0.6}, rejoin_s=30.0),
    ]
    s = handover_summary(kills, duplicates=3)
    assert (s["kills"], s["cameras_handed_over"], s["duplicates"]) == (2, 3, 3)
    assert s["p50_s"] == pytest.approx(0.4)
    assert s["max_s"] == 0.6
    assert s["rejoin_max_s"] == 30.0
    text = render_handover(kills, 3)
    assert "2 kills, 3 cameras" in text and "max 0.60 s" in text and "twice: 3" in text
    empty = handover_summary([], 0)
    assert math.isnan(empty["p50_s"]) and math.isnan(empty["max_s"])


def test_plain_rendezvous_gives_each_camera_its_top_ranked_worker() -> None:
    cameras = [f"cam{i}" for i in range(12)]
    owners = plain_rendezvous(POOL, cameras)
    for cam in cameras:
        assert owners[cam] == max(POOL, key=lambda w: rank(cam, w))


def test_weighted_rule_splits_the_heavy_cameras_where_plain_rendezvous_may_not() -> None:
    weights = {"front": 0.476, "cam1": 0.476, "cam2": 0.024, "cam3": 0.024}
    rules = compare_rules(weights, POOL, balance=1.25)
    assert set(rules) == {"weighted", "plain"}
    for per_worker in rules.values():
        cams = [c for cs, _ in per_worker.values() for c in cs]
        assert sorted(cams) == sorted(weights)  # every camera once
        assert sum(s for _, s in per_worker.values()) == pytest.approx(1.0)
    weighted = rules["weighted"]
    assert all(share <= 1.25 * 0.5 + 1e-9 for _, share in weighted.values())
    assert not any({"front", "cam1"} <= set(cs) for cs, _ in weighted.values())
    owners = assign(POOL, weights, 1.25)  # the pool's own rule, as the workers compute it
    assert {w: set(cs) for w, (cs, _) in weighted.items()} == {
        w: {c for c, o in owners.items() if o == w} for w in POOL
    }
    text = render_rules(rules, weights, heavy_together_odds(UNEVEN, POOL, 1.25, trials=50))
    assert "weighted (the pool's rule)" in text and "plain rendezvous" in text


def test_odds_over_random_names_never_put_both_heavy_cameras_together_when_weighted() -> None:
    odds = heavy_together_odds(UNEVEN, POOL, balance=1.25, trials=400, seed=1)
    assert odds["weighted"]["heavy_together"] == 0.0
    # Plain rendezvous puts the two heavy cameras on one of two workers about half the time.
    assert 0.35 < odds["plain"]["heavy_together"] < 0.65
    assert odds["weighted"]["largest_share_max"] <= 1.25 * 0.5 + 1e-9
    assert odds["plain"]["largest_share_max"] > 0.9
    assert odds == heavy_together_odds(UNEVEN, POOL, balance=1.25, trials=400, seed=1)


def test_stack_config_gives_each_camera_its_rate_and_size_and_the_workers(tmp_path: Path) -> None:
    base = load_config(None)
    config = stack_config(base, tmp_path / "s.toml", UNEVEN, tag="pool", workers=2)
    cams = config.all_cameras
    assert list(cams) == [base.stack.camera, "cam1", "cam2", "cam3"]
    assert [(c.rate_hz, c.resize) for c in cams.values()] == [
        (HEAVY.rate_hz, HEAVY.size),
        (HEAVY.rate_hz, HEAVY.size),
        (LIGHT.rate_hz, LIGHT.size),
        (LIGHT.rate_hz, LIGHT.size),
    ]
    # The simulator renders the first camera as the pool weighs it.
    assert (config.sim.width, config.sim.height) == HEAVY.size
    assert config.sim.camera_rate_hz == HEAVY.rate_hz
    assert list(config.detector_services) == list(POOL)
    assert config.supervisor.services == ("sim", "detector")
    assert config.stack.prefix.startswith("pool/")
    even = stack_config(base, tmp_path / "e.toml", [CameraLoad(5.0)] * 2, tag="scale")
    assert (even.sim.width, even.sim.height) == (base.sim.width, base.sim.height)
    assert even.detector.workers == base.detector.workers


def test_split_needs_every_worker_heard_serving_and_no_camera_twice() -> None:
    cams = ["a", "b", "c"]
    assert split({"w1": {"a"}, "w2": {"b", "c"}}, cams)
    assert split({"w1": {"a", "b", "c"}}, cams)
    assert not split({"w1": {"a"}, "w2": None}, cams)  # not heard
    assert not split({"w1": set(), "w2": {"a", "b", "c"}}, cams)  # one serves nothing
    assert not split({"w1": {"a", "b"}, "w2": {"b", "c"}}, cams)  # b twice
    assert not split({"w1": {"a"}, "w2": {"b"}}, cams)  # c missed


def test_table_and_json_show_every_condition_and_the_ratios() -> None:
    results = [
        _result(4, 1, [1.0] * 4, p50=400),
        _result(4, 2, [1.25] * 4, p50=300),
    ]
    text = render_results(results)
    lines = text.splitlines()
    assert lines[0].split()[:2] == ["setup", "det/s"]
    assert lines[2].startswith("4 cameras, 1 worker ") and "4.00" in lines[2]
    assert "detector: c0,c1 (0.50); detector_2: c2,c3 (0.50)" in lines[3]
    assert "N=4: det/s 1.25x; p50 0.75x" in text
    out = json.loads(to_json(results, [], 0, None, None, PoolOptions(), {"nproc": 2}))
    assert out["ratios"][0]["n"] == 4 and out["handover"] is None
    assert out["results"][1]["total_fps"] == 5.0


def test_options_are_checked() -> None:
    with pytest.raises(StackError):
        PoolOptions(cameras=())
    with pytest.raises(StackError):
        PoolOptions(workers=(9,))
    with pytest.raises(StackError):
        PoolOptions(seconds=0)
    with pytest.raises(StackError, match="--kills needs 2"):
        PoolOptions(workers=(1,))
    assert PoolOptions(workers=(1,), kills=0).kills == 0
    assert _counts(1, 8)("1,2") == (1, 2)
    with pytest.raises(argparse.ArgumentTypeError):
        _counts(1, 8)("9")


def test_the_capacity_part_reports_each_workers_share_gap_and_the_p95_ratio() -> None:
    from tools.benchmarks.pool_capacity import CapacityRun, render

    def run(label: str, load: float, p95: float) -> CapacityRun:
        return CapacityRun(
            label=label,
            input_size={"detector": 320, "detector_2": 640},
            capacity_hz={"detector": 30.0, "detector_2": 10.0},
            announcements={"detector": 0, "detector_2": 1},
            load_share={"detector": load, "detector_2": 1 - load},
            served={"detector": ["a"], "detector_2": ["b"]},
            fps={"a": 3.0, "b": 3.0},
            p95_ms={"a": 100.0, "b": p95},
        )

    measured, even = run("capacity", 0.7, 200.0), run("even", 0.5, 800.0)
    assert measured.capacity_share == {"detector": 0.75, "detector_2": 0.25}
    assert measured.share_gap["detector_2"] == pytest.approx(0.05)
    text = render([measured, even])
    assert "largest share gap 5% of the load (within 15 %; one camera is 50%)" in text
    far = dataclasses.replace(measured, load_share={"detector": 0.5, "detector_2": 0.5})
    assert "gap 25% of the load (NOT within 15 %" in render([far])
    assert "200 ms by capacity vs 800 ms even (0.25x)" in text
    assert json.loads(json.dumps(measured.as_dict()))["worst_p95_ms"] == 200.0


def test_the_capacity_part_reads_the_announcements_as_every_reader_does(
    capsys: pytest.CaptureFixture[str],
) -> None:
    hub = MemoryHub()
    keys = Keys("stack")
    worker = hub.join("w")
    for seq in (2, 5, 3):
        slow = WorkerAnnouncement(worker="detector_2", capacity_hz=4.0 + seq, seq=seq)
        worker.declare_token(keys.worker_announcement("detector_2", to_chunk(slow)))
    worker.declare_token(keys.worker_announcement("detector", "AAAA"))  # base64 of no message
    heard = announced(hub.join("watch"), keys)
    assert list(heard) == ["detector_2"] and heard["detector_2"].seq == 5  # the newest
    assert "a bad worker announcement ignored" in capsys.readouterr().err

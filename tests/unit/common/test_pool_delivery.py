"""Who delivers (common/pool_delivery.py): a member earns its cameras by their detections
arriving, robot by robot, and is dropped, then readmitted, when none of its cameras does."""

from __future__ import annotations

import pytest

from common.errors import ConfigError
from common.pool_audit import PoolAudit
from common.pool_delivery import MAX_READMIT_DOUBLINGS, Delivery
from common.pool_rule import PoolCamera, PoolWorker, assign_pool
from services.detector.contract import DetectorSettings

DELIVER_S = 4.0
READMIT_S = 30.0
R1, R2 = "robot1", "robot2"
CAMERAS = {f"{R1}/{c}": PoolCamera(R1, c, 5.0) for c in ("front", "rear", "left", "right")}
HONEST = PoolWorker(20.0, frozenset({R1}))
LIAR = PoolWorker(100_000.0, frozenset({R1}))  # claims everything, detects nothing


def owners(delivery: Delivery, now: float, members: dict[str, PoolWorker]) -> dict[str, str]:
    return assign_pool(members, CAMERAS, 1.0, delivery.excluded(now))


def test_a_member_that_claims_everything_and_delivers_nothing_is_dropped_then_readmitted() -> None:
    members = {"detector": HONEST, "liar": LIAR}
    d = Delivery(DELIVER_S, READMIT_S)
    given = owners(d, 0.0, members)
    assert set(given.values()) == {"liar"}, "its claim wins the cameras at first"
    assert d.judge(0.0, given, CAMERAS, members) == []
    assert d.judge(DELIVER_S, given, CAMERAS, members) == []  # within the bound
    [drop] = d.judge(DELIVER_S + 0.1, given, CAMERAS, members)
    assert (drop.robot, drop.worker, drop.cameras) == (R1, "liar", tuple(sorted(CAMERAS)))
    now = DELIVER_S + 0.1
    back = owners(d, now, members)
    assert set(back.values()) == {"detector"}, "the one that delivers takes them back"
    # The honest worker's detections arrive: it is never dropped.
    for t in range(5, 30):
        for cam in CAMERAS:
            d.saw(cam, float(t))
        assert d.judge(float(t), owners(d, float(t), members), CAMERAS, members) == []
    # Its time over, the liar is given cameras again, fails again, and waits twice as long.
    t = now + READMIT_S
    again = owners(d, t, members)
    assert set(again.values()) == {"liar"}
    assert d.judge(t, again, CAMERAS, members) == []
    [drop2] = d.judge(t + DELIVER_S + 0.1, again, CAMERAS, members)
    assert drop2.until - drop2.since == pytest.approx(2 * READMIT_S)


def test_never_everyone_and_a_member_that_delivers_is_forgiven() -> None:
    # Alone, a worker whose cameras send nothing is never dropped: nobody could take over.
    d = Delivery(DELIVER_S, READMIT_S)
    alone = {"detector": HONEST}
    given = owners(d, 0.0, alone)
    d.judge(0.0, given, CAMERAS, alone)
    assert d.judge(100.0, given, CAMERAS, alone) == []
    # A member one of whose cameras delivers is not dropped for the others.
    members = {"detector": HONEST, "other": HONEST}
    d = Delivery(DELIVER_S, READMIT_S)
    given = owners(d, 0.0, members)
    d.judge(0.0, given, CAMERAS, members)
    for t in range(1, 20):
        for cam, w in given.items():
            if w == "detector" or cam == min(c for c, o in given.items() if o == "other"):
                d.saw(cam, float(t))
        assert d.judge(float(t), given, CAMERAS, members) == []


def test_judged_robot_by_robot() -> None:
    # A worker of two robots that delivers robot2's cameras but none of robot1's is dropped
    # from robot1 only: every judge of robot1 hears robot1's detections alike.
    both = PoolWorker(100_000.0, frozenset({R1, R2}))
    cams = {**CAMERAS, f"{R2}/front": PoolCamera(R2, "front", 5.0)}
    members = {"detector": HONEST, "both": both}
    d = Delivery(DELIVER_S, READMIT_S)
    given = assign_pool(members, cams, 1.0)
    d.judge(0.0, given, cams, members)
    d.saw(f"{R2}/front", DELIVER_S)
    dropped = d.judge(DELIVER_S + 0.1, given, cams, members)
    assert [(x.robot, x.worker) for x in dropped] == [(R1, "both")]
    after = assign_pool(members, cams, 1.0, d.excluded(DELIVER_S + 0.1))
    assert after[f"{R2}/front"] == "both"
    assert {w for c, w in after.items() if c.startswith(R1)} == {"detector"}


def test_readmission_waits_double_at_most_so_often() -> None:
    d = Delivery(DELIVER_S, READMIT_S)
    members = {"detector": HONEST, "liar": LIAR}
    t, waits = 0.0, []
    for _ in range(MAX_READMIT_DOUBLINGS + 3):
        given = owners(d, t, members)
        d.judge(t, given, CAMERAS, members)
        t += DELIVER_S + 0.1
        [drop] = d.judge(t, given, CAMERAS, members)
        waits.append(drop.until - drop.since)
        t = drop.until
    assert waits[0] == READMIT_S
    assert max(waits) == READMIT_S * 2**MAX_READMIT_DOUBLINGS


def test_the_audit_warns_from_what_arrives_not_from_tokens() -> None:
    # The liar holds a serving token for every camera (forged or not): the tokens say all is
    # well, the detections do not come. The audit says unserved, then dropped.
    alarm_s = 1.0
    audit = PoolAudit({}, 1.0, alarm_s)
    members = {"detector": HONEST, "liar": LIAR}
    tokens = {("liar", "zl", c) for c in CAMERAS}
    d = Delivery(DELIVER_S, READMIT_S)
    d.judge(0.0, owners(d, 0.0, members), CAMERAS, members)

    def check(now: float) -> set[tuple[str, str]]:
        report = audit.check(
            now, members, tokens, cameras=CAMERAS, dropped=d.dropped,
            undelivered=d.undelivered(now, CAMERAS),
        )  # fmt: skip
        return {(f.kind, f.subject) for f in report.current}

    assert check(0.0) == set()
    assert check(DELIVER_S) == set()
    assert check(DELIVER_S + 0.1) == set()  # found now: an alarm once it lasts
    found = check(DELIVER_S + 0.1 + alarm_s)  # no detection: unserved, whatever the tokens
    assert found == {("unserved", c) for c in CAMERAS}
    d.judge(DELIVER_S + 2, owners(d, DELIVER_S + 2, members), CAMERAS, members)
    check(DELIVER_S + 2)
    found = check(DELIVER_S + 2 + alarm_s)
    assert ("undelivering", f"{R1}/liar") in found


def test_the_bound_must_exceed_the_attention_floors_period() -> None:
    with pytest.raises(ConfigError, match="pool_deliver_s"):
        DetectorSettings(pool_deliver_s=1.0, attention_floor_hz=0.5)
    DetectorSettings(pool_deliver_s=1.0, attention_floor_hz=0.5, attention=False)


def test_a_member_whose_token_goes_is_judged_afresh_as_a_later_judge_would() -> None:
    # A judge that joins after a member's drops knows none of its strikes; an older judge must
    # forget them too once the member's token goes, or the two readmit it at different times
    # after its next drop and place the cameras differently meanwhile.
    old, late = Delivery(DELIVER_S, READMIT_S), Delivery(DELIVER_S, READMIT_S)
    members = {"detector": HONEST, "liar": LIAR}
    t = 0.0
    for _ in range(2):  # two drops seen by the old judge alone
        given = owners(old, t, members)
        old.judge(t, given, CAMERAS, members)
        t += DELIVER_S + 0.1
        [drop] = old.judge(t, given, CAMERAS, members)
        t = drop.until
    old.left("liar")  # its process went and came back
    waits = []
    for judge in (old, late):
        given = owners(judge, t, members)
        judge.judge(t, given, CAMERAS, members)
        [drop] = judge.judge(t + DELIVER_S + 0.1, given, CAMERAS, members)
        waits.append(drop.until - drop.since)
    assert waits == pytest.approx([READMIT_S, READMIT_S])


def test_a_dropped_member_left_alone_serves_every_camera() -> None:
    # Issue 39, a CI run: a member dropped for not delivering (its link cut) stayed dropped
    # once the others left the pool, and nobody served the robot's cameras until its
    # readmission, up to pool_readmit_s x 32 later. Never every worker of a robot.
    d = Delivery(DELIVER_S, READMIT_S)
    members = {"detector": HONEST, "liar": LIAR}
    given = owners(d, 0.0, members)
    d.judge(0.0, given, CAMERAS, members)
    [drop] = d.judge(DELIVER_S + 0.1, given, CAMERAS, members)
    assert drop.worker == "liar"
    alone = {"liar": LIAR}  # the honest member's token went
    d.left("detector")
    assert set(owners(d, DELIVER_S + 1.0, alone).values()) == {"liar"}
    assert set(owners(d, DELIVER_S + 1.0, alone)) == set(CAMERAS)


def test_a_member_is_judged_on_the_detections_it_made_not_on_its_cameras() -> None:
    """The race a loaded CI run lost: the metrics service heard the liar given the cameras a
    moment after the workers did, so by its deadline the real worker, which had dropped the
    liar and taken its cameras back, was delivering them, and the liar looked as if it
    delivered: never dropped in the metrics answer. Named detections count only for the worker
    that made them; one that names no worker (an older writer) still counts for the camera's
    owner."""
    members = {"detector": HONEST, "liar": LIAR}
    late = Delivery(DELIVER_S, READMIT_S)  # a judge that heard the liar's claim at t = 2
    given = owners(late, 2.0, members)
    assert set(given.values()) == {"liar"}
    assert late.judge(2.0, given, CAMERAS, members) == []
    for t in (3.0, 4.0, 5.0, 6.0):  # the real worker has the cameras back and delivers
        for cam in CAMERAS:
            late.saw(cam, t, "detector")
    [drop] = late.judge(2.0 + DELIVER_S + 0.1, given, CAMERAS, members)
    assert drop.worker == "liar"
    # The same judge with detections that name no worker takes them as the liar's.
    anonymous = Delivery(DELIVER_S, READMIT_S)
    anonymous.judge(2.0, given, CAMERAS, members)
    for t in (3.0, 4.0, 5.0, 6.0):
        for cam in CAMERAS:
            anonymous.saw(cam, t)
    assert anonymous.judge(2.0 + DELIVER_S + 0.1, given, CAMERAS, members) == []
    # The member's own named detections count.
    own = Delivery(DELIVER_S, READMIT_S)
    own.judge(2.0, given, CAMERAS, members)
    own.saw(next(iter(CAMERAS)), 5.0, "liar")
    assert own.judge(2.0 + DELIVER_S + 0.1, given, CAMERAS, members) == []

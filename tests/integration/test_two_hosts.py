"""Two hosts for real: two network namespaces joined by a veth pair, as docs/pool.md says.

    namespace A ("GPU box", 10.77.0.1)            namespace B ("robot", 10.77.0.2)
    supervisor A: services = ["detector"]         supervisor B: camera, controller, metrics
      a router on tcp/127.0.0.1:7447 (its own)      a router on tcp/10.77.0.2:7447
      which connects to tcp/10.77.0.2:7447          the test's probe (tests/integration/probe.py)

Client mode: each supervisor is a Zenoh router, each service (and the probe) a client of its own
host's router, and the two routers link across the veth pair. Then the link is cut for longer
than Zenoh's lease, so the session across it closes, and restored. Not peer mode: there every
pair of processes must meet again after the cut, and one run in six left the controller without
detections for good while the probe beside it had them (docs/pool.md, "Client mode on both hosts").

The third test runs that pool under the secure profile: mutual TLS on every link, the two
routers' link included, and access control on both routers (docs/security.md, "Two hosts,
secured").

The second test runs a detector pool across the two hosts: a worker on each (``worker_id``
"a" on A, "b" on B, so ``detector_a`` and ``detector_b``), both cameras on B. They split the
cameras; with the link cut past the lease B's worker serves both (and A's, alone, takes both
too, with no frame to detect); with the link back they split again, nothing restarted.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import pytest

from common.security import ROUTER_PRINCIPAL, ca_file, cert_file, key_file, stack_principals
from common.settings import principal_name
from deploy.credentials import generate
from tests.integration.conftest import REPO, STARTUP_S, wait_for, write_config
from tests.integration.netns import ip
from tools.launch import service_pids

pytestmark = pytest.mark.integration

ADDR_A, ADDR_B, PORT = "10.77.0.1", "10.77.0.2", 7447  # private namespaces: no port clash
DEAD_MAN_S = 2.0  # controller.detection_timeout_s: inference takes ~1 s on a loaded 2-core CI box
MARGIN_S = 1.0  # one control tick, scheduling on a loaded machine
LEASE_S = 10.0  # Zenoh's default lease: a silent peer is dropped after it
MODE = "client"  # routers on both hosts: docs/pool.md


@dataclass
class Hosts:
    """Two namespaces (unique per run) and a veth pair between them."""

    a: str
    b: str
    veth_a: str
    procs: list[subprocess.Popen[bytes]] = field(default_factory=list)

    def run(self, ns: str, args: list[str], out: IO[bytes]) -> subprocess.Popen[bytes]:
        proc = subprocess.Popen(
            ["ip", "netns", "exec", ns, sys.executable, *args],
            cwd=REPO, env={**os.environ, "PYTHONUNBUFFERED": "1"},
            stdout=out, stderr=subprocess.STDOUT if out is not subprocess.PIPE else None,
            start_new_session=True,
        )  # fmt: skip
        self.procs.append(proc)
        return proc

    def link(self, up: bool) -> float:
        ip("-n", self.a, "link", "set", self.veth_a, "up" if up else "down")
        return time.monotonic()


@pytest.fixture
def hosts() -> Iterator[Hosts]:
    if os.geteuid() != 0:
        pytest.skip("needs root to create network namespaces (ip netns)")
    if shutil.which("ip") is None:
        pytest.skip("needs iproute2's `ip` for network namespaces")
    tag = uuid.uuid4().hex[:6]
    h = Hosts(a=f"zys-{tag}-a", b=f"zys-{tag}-b", veth_a=f"zy{tag}a")
    veth_b = f"zy{tag}b"
    try:
        ip("netns", "add", h.a)
    except RuntimeError as exc:
        pytest.skip(f"cannot create a network namespace here: {exc}")
    try:
        ip("netns", "add", h.b)
        ip("link", "add", h.veth_a, "type", "veth", "peer", "name", veth_b)
        for ns, dev, addr in ((h.a, h.veth_a, ADDR_A), (h.b, veth_b, ADDR_B)):
            ip("link", "set", dev, "netns", ns)
            ip("-n", ns, "addr", "add", f"{addr}/24", "dev", dev)
            ip("-n", ns, "link", "set", dev, "up")
            ip("-n", ns, "link", "set", "lo", "up")
        yield h
    finally:
        for proc in h.procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        for ns in (h.a, h.b):  # deleting a namespace deletes its end of the veth pair too
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)


class Probe:
    """What the probe in namespace B saw: one dict per sample (tests/integration/probe.py)."""

    def __init__(self, proc: subprocess.Popen[bytes]) -> None:
        self.events: list[dict[str, Any]] = []
        assert proc.stdout is not None
        self._thread = threading.Thread(target=self._read, args=(proc.stdout,), daemon=True)
        self._thread.start()

    def _read(self, stream: IO[bytes]) -> None:
        for line in stream:
            if line.startswith(b"{"):
                self.events.append(json.loads(line))

    def of(self, kind: str, after: float = 0.0, before: float = math.inf) -> list[dict[str, Any]]:
        return [e for e in list(self.events) if e["kind"] == kind and after <= e["t"] < before]

    def health(self, service: str, present: bool, after: float) -> bool:
        events = self.of("health", after)
        return any(e["service"] == service and e["present"] is present for e in events)

    def recent(self, after: float) -> str:
        """The newest detections and controller states seen since ``after``, for a failure."""
        dets = [(round(e["t"] - after, 1), e["classes"], round(e["age_ms"])) for e in
                self.of("detections", after)[-5:]]  # fmt: skip
        states = [(round(e["t"] - after, 1), e["state"], e["reason"]) for e in
                  self.of("status", after)[-5:]]  # fmt: skip
        return f"detections (t, classes, age ms): {dets}; controller: {states}"

    def moving(self, after: float) -> bool:
        return any(not c["zero"] for c in self.of("cmd_vel", after))


def _log(path: Path) -> str:
    return path.read_text(errors="replace")[-5000:]


def test_detector_on_another_host_survives_a_cut_link(hosts: Hosts, tmp_path: Path) -> None:
    prefix = f"test/{uuid.uuid4().hex[:8]}"
    stack = {"prefix": prefix, "camera": "front"}
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    robot = write_config(
        tmp_path / "b",
        zenoh={"endpoint": f"tcp/{ADDR_B}:{PORT}", "mode": MODE},
        stack=stack,
        supervisor={"services": ["camera", "controller", "metrics"]},
        controller={"mode": "track", "detection_timeout_s": DEAD_MAN_S},
    )
    gpu_box = write_config(
        tmp_path / "a",
        zenoh={
            "endpoint": f"tcp/127.0.0.1:{PORT}",
            "connect": [f"tcp/{ADDR_B}:{PORT}"],
            "mode": MODE,
        },
        stack=stack,
        supervisor={"services": ["detector"]},
    )
    log_a, log_b = tmp_path / "a.log", tmp_path / "b.log"
    supervise = ["-m", "deploy.supervisor", "--config"]
    sup_b = hosts.run(hosts.b, [*supervise, str(robot)], log_b.open("wb"))
    sup_a = hosts.run(hosts.a, [*supervise, str(gpu_box)], log_a.open("wb"))
    probe_args = ["-m", "tests.integration.probe", "--config", str(robot)]
    probe = Probe(hosts.run(hosts.b, probe_args, subprocess.PIPE))

    def logs() -> str:
        return f"--- host A:\n{_log(log_a)}\n--- host B:\n{_log(log_b)}"

    # Across the link: frames B -> A, detections A -> B, and the robot follows.
    wait_for(lambda: probe.moving(0.0), STARTUP_S, lambda: f"a non-zero command:\n{logs()}")
    assert any("person" in d["classes"] for d in probe.of("detections"))
    [detector] = service_pids("detector", gpu_box)

    cut = hosts.link(up=False)
    wait_for(lambda: probe.of("cmd_vel", cut + DEAD_MAN_S), 10, "commands after the cut")
    first_zero = min(c["t"] for c in probe.of("cmd_vel", cut) if c["zero"])
    assert first_zero - cut <= DEAD_MAN_S + MARGIN_S, "no stop within the dead-man timeout"
    # Longer than the lease: B drops the detector's session (its health token goes).
    wait_for(lambda: probe.health("detector", False, cut), 2 * LEASE_S + 10, "B to drop host A")
    restored = hosts.link(up=True)
    stopped_from = cut + DEAD_MAN_S + MARGIN_S
    cut_off = probe.of("cmd_vel", stopped_from, restored)
    assert cut_off and all(c["zero"] for c in cut_off), "the robot moved with no detections"
    assert not probe.of("detections", cut + MARGIN_S, restored)

    # The link is back: Zenoh reconnects by itself, detections resume, the robot follows.
    wait_for(lambda: probe.health("detector", True, restored), 60, lambda: f"A back:\n{logs()}")
    wait_for(lambda: probe.of("detections", restored), 30, "detections after the link is back")
    wait_for(
        lambda: probe.moving(restored), 30,
        lambda: f"the robot to follow again; {probe.recent(restored)}\n{logs()}",
    )  # fmt: skip
    dropped = min(e["t"] for e in probe.of("health", cut) if not e["present"])
    back = min(e["t"] for e in probe.of("detections", restored))
    moving = min(c["t"] for c in probe.of("cmd_vel", restored) if not c["zero"])
    print(
        f"link cut: zero command after {first_zero - cut:.2f} s, host A dropped after "
        f"{dropped - cut:.1f} s; link back: detections after {back - restored:.1f} s, "
        f"following after {moving - restored:.1f} s"
    )
    # Nothing was restarted, by hand or by either watchdog: A's detector kept its health token
    # and its heartbeat with A's own supervisor, and B's services never depended on host A.
    assert service_pids("detector", gpu_box) == [detector]
    _nothing_restarted_and_both_stop(log_a, log_b, sup_a, sup_b, logs)


def _start_pool_hosts(
    hosts: Hosts, tmp_path: Path, robot: Path, gpu_box: Path
) -> tuple[Path, Path, subprocess.Popen[bytes], subprocess.Popen[bytes], Probe]:
    """Host B's supervisor (the robot) and A's (the GPU box), and a probe on B: their logs,
    the two supervisors and the probe."""
    log_a, log_b = tmp_path / "a.log", tmp_path / "b.log"
    supervise = ["-m", "deploy.supervisor", "--config"]
    sup_b = hosts.run(hosts.b, [*supervise, str(robot)], log_b.open("wb"))
    sup_a = hosts.run(hosts.a, [*supervise, str(gpu_box)], log_a.open("wb"))
    probe = Probe(hosts.run(hosts.b, ["-m", "tests.integration.probe", "--config", str(robot)],
                            subprocess.PIPE))  # fmt: skip
    return log_a, log_b, sup_a, sup_b, probe


def _nothing_restarted_and_both_stop(
    log_a: Path,
    log_b: Path,
    sup_a: subprocess.Popen[bytes],
    sup_b: subprocess.Popen[bytes],
    logs: Callable[[], str],
) -> None:
    """No service of either host was found hung or restarted, and both supervisors stop
    cleanly on SIGINT."""
    for name, path in (("A", log_a), ("B", log_b)):
        text = path.read_text(errors="replace")
        assert "hung (" not in text and "restarted" not in text, f"host {name}:\n{logs()}"
    for proc in (sup_a, sup_b):
        proc.send_signal(signal.SIGINT)
    for name, proc in (("A", sup_a), ("B", sup_b)):
        assert proc.wait(timeout=30) == 0, f"supervisor {name}:\n{logs()}"


# --- A detector pool across the two hosts (issue 23) -------------------------------------------

#: Both hosts' configs list the same cameras, as the pool needs (each worker weighs them from
#: its own config): all on host B, the robot.
POOL_CAMERAS = {"front": "cameraman", "rear": "astronaut"}
POOL_WORKERS = {"a": "detector_a", "b": "detector_b"}  # detector.worker_id -> its worker
POOL_CAPACITY_HZ = 10.0  # detector.capacity_hz of both workers


def _pool_tables(stack: dict[str, str], worker_id: str) -> dict[str, Any]:
    cams = {n: {"source": f"sample:{s}", "frame_id": n} for n, s in POOL_CAMERAS.items()}
    return {
        "stack": stack,
        "camera": {**cams["front"], "rate_hz": 3.0, "resize": [320, 240]},
        "cameras.rear": cams["rear"],
        # One stated capacity for both workers: shares follow capacity, and one measured at
        # start on a loaded machine may be twice the other's, which would give one worker
        # both cameras; these tests are about the split across hosts, not the measure.
        "detector": {"worker_id": worker_id, "imgsz": 320, "capacity_hz": POOL_CAPACITY_HZ},
    }


def _serving(probe: Probe, after: float) -> dict[str, set[str]]:
    """Each worker's cameras, from its latest counters heard on host B after ``after``."""
    out: dict[str, set[str]] = {}
    for e in probe.of("worker", after):
        out[e["service"]] = set(e["serving"])
    return out


def _shared(probe: Probe, after: float) -> dict[str, set[str]] | None:
    split = _serving(probe, after)
    cams = [split.get(w, set()) for w in POOL_WORKERS.values()]
    if all(len(c) == 1 for c in cams) and set.union(*cams) == set(POOL_CAMERAS):
        return split
    return None


def _metrics_workers(ns: str, config: Path) -> dict[str, set[str]]:
    """The workers (and their cameras) in the answer of the metrics service of namespace ``ns``,
    asked as a user would (``zstack query``); {} while it has none to give."""
    done = subprocess.run(
        ["ip", "netns", "exec", ns, sys.executable, "-m", "services.metrics", "query",
         "--config", str(config), "--timeout", "2"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    if done.returncode != 0:
        return {}
    answer = json.loads(done.stdout)
    return {w: set(m["cameras"]) for w, m in (answer.get("workers") or {}).items()}


def _detected(probe: Probe, after: float) -> bool:
    """Every camera detected after ``after``."""
    return {e["camera"] for e in probe.of("detections", after)} >= set(POOL_CAMERAS)


def test_a_pool_across_two_hosts_shares_splits_and_settles_with_no_restart(
    hosts: Hosts, tmp_path: Path
) -> None:
    prefix = f"test/{uuid.uuid4().hex[:8]}"
    stack = {"prefix": prefix, "camera": "front"}
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    robot = write_config(
        tmp_path / "b",
        zenoh={"endpoint": f"tcp/{ADDR_B}:{PORT}", "mode": MODE},
        supervisor={"services": ["camera", "detector", "metrics"]},
        **_pool_tables(stack, "b"),
    )
    gpu_box = write_config(
        tmp_path / "a",
        zenoh={
            "endpoint": f"tcp/127.0.0.1:{PORT}",
            "connect": [f"tcp/{ADDR_B}:{PORT}"],
            "mode": MODE,
        },
        supervisor={"services": ["detector"]},
        **_pool_tables(stack, "a"),
    )
    log_a, log_b, sup_a, sup_b, probe = _start_pool_hosts(hosts, tmp_path, robot, gpu_box)
    worker_a, worker_b = POOL_WORKERS["a"], POOL_WORKERS["b"]

    def logs() -> str:
        return f"--- host A:\n{_log(log_a)}\n--- host B:\n{_log(log_b)}"

    # Steady state: one camera each, both detected on the robot.
    split = wait_for(lambda: _shared(probe, 0.0), STARTUP_S, lambda: f"a split:\n{logs()}")
    settled = time.monotonic()
    wait_for(lambda: _detected(probe, settled), 30, lambda: f"both cameras detected:\n{logs()}")
    pids = {w: service_pids(w, cfg) for w, cfg in ((worker_a, gpu_box), (worker_b, robot))}
    assert all(len(p) == 1 for p in pids.values()), pids
    # The robot's metrics show both workers, host A's too, which its config does not name.
    wait_for(lambda: _metrics_workers(hosts.b, robot) == split, 30, "both workers in B's metrics")

    # The link cut for longer than the lease: B's worker serves every camera once A's token
    # goes, and A's worker is alone in its pool. What A then serves depends on which of B's
    # tokens its router drops first: B's worker's (A takes both cameras, still announced, then
    # drops them as their announcements go) or all at once (A serves none): it gets no frame
    # either way, and is never in a pool of two over a cut link.
    seen_a = len(log_a.read_text(errors="replace"))
    cut = hosts.link(up=False)
    alone = wait_for(
        lambda: next((e["t"] for e in probe.of("worker", cut) if e["service"] == worker_b
                      and set(e["serving"]) == set(POOL_CAMERAS)), None),
        2 * LEASE_S + 10, lambda: f"{worker_b} to serve every camera:\n{logs()}",
    )  # fmt: skip
    wait_for(lambda: _detected(probe, alone), 30, lambda: f"B's worker detecting all:\n{logs()}")
    # A hears B's token go only when the lease runs out; B may have taken A's cameras well
    # before, as soon as A delivered nothing on them (detector.pool_deliver_s).
    wait_for(
        lambda: "pool of 1: serving" in log_a.read_text(errors="replace")[seen_a:],
        max(0.0, cut + 2 * LEASE_S + 10 - time.monotonic()),
        lambda: f"{worker_a} to be alone in its pool:\n{logs()}",
    )  # fmt: skip

    # The link back: the routers meet again, each worker hears the other, and they split the
    # cameras as before, with nothing restarted.
    restored = hosts.link(up=True)
    again = wait_for(lambda: _shared(probe, restored), 60, lambda: f"a split again:\n{logs()}")
    shared_at = time.monotonic()
    wait_for(lambda: _detected(probe, shared_at), 30, lambda: f"both detected again:\n{logs()}")
    assert again == split, "the same membership gave another assignment"
    print(
        f"pool across hosts: split {split}; link cut: {worker_b} serves every camera after "
        f"{alone - cut:.1f} s; link back: shared again after {shared_at - restored:.1f} s"
    )
    assert {w: service_pids(w, cfg) for w, cfg in
            ((worker_a, gpu_box), (worker_b, robot))} == pids  # fmt: skip
    _nothing_restarted_and_both_stop(log_a, log_b, sup_a, sup_b, logs)


# --- The secure profile across the two hosts (issue 31, item 6) --------------------------------

#: The principals host B (the robot) runs, the test's probe included: what host A's router
#: lets B's router do over their link (zenoh.remote_principals). B's router lets A's do what
#: A's one worker may.
ROBOT_PRINCIPALS = ("camera", "camera_rear", "detector_b", "controller", "metrics", "observer")
GPU_PRINCIPALS = ("detector_a",)
CAMERA_PRINCIPALS = {"front": "camera", "rear": "camera_rear"}  # POOL_CAMERAS' principals
#: Rogue detections heard before the forbidden puts sent in the same rounds are judged: each
#: round puts the forbidden keys first, so by then each was put this many times.
ROGUE_ROUNDS = 20


def _host_credentials(made: Path, host: Path, prefix: str, roles: tuple[str, ...]) -> Path:
    """A host's own credentials folder: the CA, the router's certificate and key
    (``<prefix>/supervisor``: both hosts are the one robot's stack, both routers serve and link
    with it) and those of the principals it runs (``roles`` of the
    stack of ``prefix``), copied from the one set ``made`` for every host, each at its place
    (docs/security.md, "Two hosts, secured")."""
    host.mkdir(mode=0o700)
    for principal in (principal_name(prefix, r) for r in (ROUTER_PRINCIPAL, *roles)):
        for path in (cert_file(made, principal), key_file(made, principal)):
            copy = host / path.relative_to(made)
            copy.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
            shutil.copy2(path, copy)
    shutil.copy2(ca_file(made), host / ca_file(made).name)
    return host


def _rogue(hosts: Hosts, ns: str, config: Path, *args: str) -> subprocess.Popen[bytes]:
    return hosts.run(ns, ["-m", "tests.integration.rogue", "--config", str(config), *args],
                     subprocess.PIPE)  # fmt: skip


def _refused_without_a_certificate(ns: str, config: Path) -> str:
    """What a client with no certificate of its own got from the router of ``config``."""
    done = subprocess.run(
        ["ip", "netns", "exec", ns, sys.executable, "-m", "tests.integration.rogue",
         "--config", str(config), "--as", "observer", "--no-cert"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    lines = [json.loads(ln) for ln in done.stdout.splitlines() if ln.startswith("{")]
    assert lines, f"no answer:\n{done.stdout}\n{done.stderr}"
    return str(lines[-1]["kind"])


def test_the_secure_profile_across_two_linked_routers_confines_every_principal(
    hosts: Hosts, tmp_path: Path
) -> None:
    """Mutual TLS on every link, the routers' included, and access control on both routers:
    a worker on each host serves its share of B's cameras; A's worker may put nothing but
    detections (A's router drops the rest), a session with the router's own certificate
    connecting to B (a linked router) may put nothing but what A's principals may (B's router
    drops the rest), and a client without a certificate joins neither router."""
    prefix = f"test/{uuid.uuid4().hex[:8]}"
    stack = {"prefix": prefix, "camera": "front"}
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    made = tmp_path / "made"
    workers = ("detector_b", *GPU_PRINCIPALS)
    names = tuple(principal_name(prefix, p) for p in stack_principals(CAMERA_PRINCIPALS, workers))
    generate(made, hosts=(ADDR_B,), principals=names)
    creds_b = _host_credentials(made, tmp_path / "creds_b", prefix, ROBOT_PRINCIPALS)
    creds_a = _host_credentials(made, tmp_path / "creds_a", prefix, GPU_PRINCIPALS)
    secure = {"mode": MODE, "auth": "certificate"}
    robot = write_config(
        tmp_path / "b",
        zenoh={**secure, "endpoint": f"tls/{ADDR_B}:{PORT}", "credentials_dir": str(creds_b),
               "remote_principals": list(GPU_PRINCIPALS)},
        supervisor={"services": ["camera", "detector", "controller", "metrics"]},
        **_pool_tables(stack, "b"),
    )  # fmt: skip
    gpu_box = write_config(
        tmp_path / "a",
        zenoh={**secure, "endpoint": f"tls/127.0.0.1:{PORT}", "connect": [f"tls/{ADDR_B}:{PORT}"],
               "credentials_dir": str(creds_a), "remote_principals": list(ROBOT_PRINCIPALS)},
        supervisor={"services": ["detector"]},
        **_pool_tables(stack, "a"),
    )  # fmt: skip
    log_a, log_b, sup_a, sup_b, probe = _start_pool_hosts(hosts, tmp_path, robot, gpu_box)

    def logs() -> str:
        return f"--- host A:\n{_log(log_a)}\n--- host B:\n{_log(log_b)}"

    # Across the secured link: a camera each, both detected on the robot, frames B -> A and
    # detections and counters A -> B through both routers' rules.
    split = wait_for(lambda: _shared(probe, 0.0), STARTUP_S, lambda: f"a split:\n{logs()}")
    settled = time.monotonic()
    wait_for(lambda: _detected(probe, settled), 30, lambda: f"both cameras detected:\n{logs()}")

    # A client without a certificate joins neither router.
    assert _refused_without_a_certificate(hosts.a, gpu_box) == "refused"
    assert _refused_without_a_certificate(hosts.b, robot) == "refused"

    # A's worker's principal through A's router, and the router's own certificate straight
    # into B's router (as a linked router arrives): each puts garbage on cmd_vel, the e-stop
    # and every camera's frames, and empty detections, which only may pass.
    rogues = {
        "detector_a": _rogue(hosts, hosts.a, gpu_box, "--as", "detector_a"),
        ROUTER_PRINCIPAL: _rogue(hosts, hosts.a, gpu_box, "--as", ROUTER_PRINCIPAL,
                                 "--endpoint", f"tls/{ADDR_B}:{PORT}"),
    }  # fmt: skip
    rogue_from = time.monotonic()

    def rogue_detections(principal: str) -> int:
        return sum(1 for e in probe.of("detections", rogue_from)
                   if e["source"] == f"rogue-{principal}")  # fmt: skip

    wait_for(
        lambda: all(rogue_detections(p) >= ROGUE_ROUNDS * len(POOL_CAMERAS) for p in rogues),
        60, lambda: f"the rogues' detections: {[rogue_detections(p) for p in rogues]}\n{logs()}",
    )  # fmt: skip
    judged = time.monotonic()
    # Each worker's counters once more after that, which would count any garbage frame.
    workers_heard = lambda: {e["service"] for e in probe.of("worker", judged)}  # noqa: E731
    wait_for(lambda: workers_heard() >= set(POOL_WORKERS.values()), 30, "both workers' counters")
    for proc in rogues.values():
        proc.send_signal(signal.SIGINT)
    garbage = [e for e in probe.of("garbage", rogue_from) if e["key"].endswith("cmd_vel")]
    assert garbage == [], f"rogue commands reached the robot: {garbage[:3]}"
    estop = [e for e in probe.of("status", rogue_from) if e["state"] == "estop"]
    assert estop == [], f"a rogue e-stop reached the controller: {estop[:3]}"
    bad = [e for e in probe.of("worker", rogue_from) if e["bad_frames"]]
    assert bad == [], f"rogue frames reached a worker: {bad[:3]}"
    assert _shared(probe, judged) == split, "the split moved"
    print(
        f"secured across hosts: split {split}; rogue detections heard "
        f"{ {p: rogue_detections(p) for p in rogues} }, nothing else of theirs"
    )
    for name, proc in rogues.items():
        assert proc.wait(timeout=30) == 0, f"rogue {name}"
    _nothing_restarted_and_both_stop(log_a, log_b, sup_a, sup_b, logs)

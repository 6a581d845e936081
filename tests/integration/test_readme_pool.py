"""The GPU box beside a robot of docs/pool.md, run as written on two network namespaces.

    namespace A, the GPU box: gpu.toml               namespace B, the robot (10.78.0.2): robot.toml
      `zstack prepare`, then `zstack run`              `zstack run`: cameras, a CPU worker,
      (one detector worker, no camera table)           controller, metrics; the test's eyes
                                                       (pool_view.py, `zstack query`)

The two configs are taken from docs/pool.md's ```toml blocks named ``# robot.toml`` and
``# gpu.toml`` (tests/readme.py) with only the changes :func:`tests.readme.as_tested` makes:
the robot's address is namespace B's, the cameras' ``device:N`` are bundled photos (a person
in front, a cat behind), the GPU backend is ONNX Runtime on the CPU (no GPU here) and, for the
secured pair (``# robot-secure.toml``, ``# gpu-secure.toml`` of docs/security.md, which
extend the plain ones), ``zenoh.credentials_dir`` is the test's folder, the credentials made
as docs/security.md says. Both workers join, the cameras are split as the pool's rule splits
them by the capacities the workers announce, each camera is served (and its detections
published) by exactly one worker, the robot's controller gets detections of every camera and
targets the person, and
`zstack query` on the robot shows what docs/pool.md says it shows.

docs/pool.md's several robots (``# gpu-box.toml``, ``# robot1.toml``, robot2 made from robot1
as the page says) run on three namespaces, the GPU box linked to each robot: its one worker
serves both robots' cameras, each robot's controller fresh on its own.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import pytest

from common.pool_rule import assign
from common.security import ROUTER_PRINCIPAL, ca_file, cert_file, key_file
from stack.config_file import load_config
from tests.integration.conftest import REPO, STARTUP_S, wait_for
from tests.integration.netns import ip
from tests.readme import (
    ROBOT1_ADDRESS,
    ROBOT2_ADDRESS,
    ROBOT_ADDRESS,
    as_tested,
    named_block,
    with_credentials,
)

pytestmark = pytest.mark.integration

ADDR_A, ADDR_B = "10.78.0.1", "10.78.0.2"  # private namespaces: no clash with anything
SAMPLES = ("astronaut", "chelsea")  # device:0 (front) sees a person, device:1 (rear) a cat
PERSON_CAMERA = "front"
WORKERS = ("detector_gpu", "detector_robot")  # docs/pool.md: worker_id "gpu" and "robot"
#: docs/pool.md, "Several robots on one pool": the GPU box linked to each robot's router,
#: a /24 each.
SITE = [("gpu", "10.79.1.1", "robot1", "10.79.1.2"), ("gpu", "10.79.2.1", "robot2", "10.79.2.2")]
SITE_ADDRESSES = {ROBOT1_ADDRESS: "10.79.1.2", ROBOT2_ADDRESS: "10.79.2.2"}
SETTLE_S = 2 * STARTUP_S  # two CPU workers measuring their capacity on a loaded 2-core box


@dataclass
class Hosts:
    """Network namespaces (unique per run) joined by veth pairs, by role; the processes
    started in them."""

    ns: dict[str, str]
    #: Each host's own temporary folder (TMPDIR), as on real hosts: the supervisor's lock
    #: (deploy/lock.py) is named after the endpoint and prefix, which two tests' GPU boxes
    #: share (docs/pool.md's), and namespaces share this machine's /tmp.
    tmp: dict[str, str] = field(default_factory=dict)
    procs: list[subprocess.Popen[bytes]] = field(default_factory=list)

    @property
    def a(self) -> str:
        return self.ns["a"]

    @property
    def b(self) -> str:
        return self.ns["b"]

    def _args(self, ns: str, args: list[str]) -> list[str]:
        return ["ip", "netns", "exec", ns, sys.executable, *args]

    def _env(self, ns: str) -> dict[str, str]:
        return {**os.environ, "PYTHONUNBUFFERED": "1", "TMPDIR": self.tmp[ns]}

    def start(self, ns: str, args: list[str], out: IO[bytes]) -> subprocess.Popen[bytes]:
        proc = subprocess.Popen(
            self._args(ns, args), cwd=REPO, env=self._env(ns),
            stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip
        self.procs.append(proc)
        return proc

    def call(self, ns: str, args: list[str], timeout: float) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            self._args(ns, args), cwd=REPO, env=self._env(ns), capture_output=True, text=True,
            timeout=timeout,
        )  # fmt: skip


#: A link: (role, its address, role, its address), one veth pair in a /24 of its own.
Link = tuple[str, str, str, str]


def _network(links: list[Link]) -> Iterator[Hosts]:
    if os.geteuid() != 0:
        pytest.skip("needs root to create network namespaces (ip netns)")
    if shutil.which("ip") is None:
        pytest.skip("needs iproute2's `ip` for network namespaces")
    tag = uuid.uuid4().hex[:6]
    roles = sorted({r for link in links for r in (link[0], link[2])})
    h = Hosts(ns={r: f"zyr-{tag}-{r}" for r in roles})
    made: list[str] = []
    try:
        h.tmp = {ns: tempfile.mkdtemp(prefix=f"{ns}-") for ns in h.ns.values()}
        for ns in h.ns.values():
            try:
                ip("netns", "add", ns)
            except RuntimeError as exc:
                pytest.skip(f"cannot create a network namespace here: {exc}")
            made.append(ns)
            ip("-n", ns, "link", "set", "lo", "up")
        for i, (role_1, addr_1, role_2, addr_2) in enumerate(links):
            dev_1, dev_2 = f"zr{tag}{i}x", f"zr{tag}{i}y"
            ip("link", "add", dev_1, "type", "veth", "peer", "name", dev_2)
            for role, dev, addr in ((role_1, dev_1, addr_1), (role_2, dev_2, addr_2)):
                ip("link", "set", dev, "netns", h.ns[role])
                ip("-n", h.ns[role], "addr", "add", f"{addr}/24", "dev", dev)
                ip("-n", h.ns[role], "link", "set", dev, "up")
        yield h
    finally:
        for proc in h.procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        for ns in made:  # deleting a namespace deletes its ends of the veth pairs too
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)
        for folder in h.tmp.values():
            shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def hosts() -> Iterator[Hosts]:
    """A, the GPU box, and B, the robot."""
    yield from _network([("a", ADDR_A, "b", ADDR_B)])


def _write(where: Path, name: str, credentials: Path | None = None) -> Path:
    where.mkdir(exist_ok=True)
    text = as_tested(named_block(name).text, addresses={ROBOT_ADDRESS: ADDR_B}, samples=SAMPLES)
    path = where / name
    path.write_text(text if credentials is None else with_credentials(text, credentials))
    return path


def _configs(tmp_path: Path, secure: bool) -> tuple[Path, Path]:
    """The robot's and the GPU box's configs, each in a folder of its own. Secured: the plain
    ones beside them (they extend those), and the credentials made once, on the robot, as the
    page says; the GPU box gets a copy of the CA, the router's and its worker's files."""
    robot, gpu = _write(tmp_path / "robot", "robot.toml"), _write(tmp_path / "gpu", "gpu.toml")
    if secure:
        made, copied = tmp_path / "secrets_robot", tmp_path / "secrets_gpu"
        robot = _write(tmp_path / "robot", "robot-secure.toml", made)
        gpu = _write(tmp_path / "gpu", "gpu-secure.toml", copied)
        done = subprocess.run(
            [sys.executable, "-m", "deploy.zstack", "credentials", "--config", str(robot),
             "--host", ADDR_B],
            cwd=REPO, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr[-2000:]
        copied.mkdir(mode=0o700)
        box = load_config(gpu, environ={})
        worker = box.principal(f"detector_{box.detector.worker_id}")  # stack/detector_gpu
        for principal in (box.principal(ROUTER_PRINCIPAL), worker):  # stack/supervisor
            for file in (cert_file(made, principal), key_file(made, principal)):
                copy = copied / file.relative_to(made)  # each at its place: stack/...
                copy.parent.mkdir(mode=0o700, exist_ok=True)
                shutil.copy2(file, copy)
        shutil.copy2(ca_file(made), copied / ca_file(made).name)
    for path in (robot, gpu):
        load_config(path, environ={})  # one clear line here if a docs block does not load
    return robot, gpu


def _view(hosts: Hosts, robot: Path) -> dict[str, Any] | None:
    """The pool as seen on the robot over a few seconds (tests/integration/pool_view.py)."""
    args = ["-m", "tests.integration.pool_view", "--config", str(robot), "--seconds", "4"]
    done = hosts.call(hosts.b, args, timeout=60)
    return json.loads(done.stdout) if done.returncode == 0 else None


def _settled(view: dict[str, Any] | None, balance: float) -> bool:
    """Both workers announced; every camera served by one of them, the same at the start and
    the end of the window, as the pool's rule splits the cameras' rates by the capacities
    announced; each camera's detections from one publisher; and the controller fresh on every
    camera at least once, its target on the person's camera."""
    if view is None or sorted(view["workers"]) != sorted(WORKERS) or not view["cameras"]:
        return False
    serving = view["serving"]
    owner = {c: w for w, cams in serving.items() for c in cams}
    capacities = {w: a["capacity_hz"] for w, a in view["workers"].items()}
    stale_sets = view["controller"]["stale_sets"]
    fresh = {c for c in view["cameras"] if any(c not in stale for stale in stale_sets)}
    return (
        serving == view["serving_before"]
        and sum(len(cams) for cams in serving.values()) == len(view["cameras"])
        and owner == assign(capacities, view["cameras"], balance)
        and all(view["publishers"].get(c) == 1 for c in view["cameras"])
        and fresh == set(view["cameras"])
        and PERSON_CAMERA in view["controller"]["target_cameras"]
    )


def _query(hosts: Hosts, robot: Path) -> dict[str, Any] | None:
    """``zstack query --config robot.toml`` on the robot, as docs/pool.md says to check."""
    args = ["-m", "deploy.zstack", "query", "--config", str(robot), "--timeout", "2"]
    done = hosts.call(hosts.b, args, timeout=60)
    return json.loads(done.stdout) if done.returncode == 0 else None


@pytest.mark.parametrize("secure", [False, True], ids=["plain", "secured"])
def test_the_readme_gpu_box_and_robot_run_as_written(
    hosts: Hosts, tmp_path: Path, secure: bool
) -> None:
    robot, gpu = _configs(tmp_path, secure)
    prepared = hosts.call(hosts.a, ["-m", "deploy.zstack", "prepare", "--config", str(gpu)], 600)
    assert prepared.returncode == 0, prepared.stderr[-2000:]
    log_a, log_b = tmp_path / "gpu.log", tmp_path / "robot.log"
    sup_b = hosts.start(hosts.b, ["-m", "deploy.zstack", "run", "--config", str(robot)],
                        log_b.open("wb"))  # fmt: skip
    sup_a = hosts.start(hosts.a, ["-m", "deploy.zstack", "run", "--config", str(gpu)],
                        log_a.open("wb"))  # fmt: skip
    last: list[dict[str, Any] | None] = [None]

    def logs() -> str:
        tails = (p.read_text(errors="replace")[-4000:] for p in (log_a, log_b))
        return "last view: {}\n--- GPU box:\n{}\n--- robot:\n{}".format(last[0], *tails)

    balance = load_config(robot, environ={}).detector.pool_balance

    def settled() -> dict[str, Any] | None:
        for name, proc in (("GPU box", sup_a), ("robot", sup_b)):
            if proc.poll() is not None:  # a config the supervisor refuses: say so at once
                pytest.fail(f"{name}'s supervisor exited ({proc.returncode}):\n{logs()}")
        last[0] = _view(hosts, robot)
        return last[0] if _settled(last[0], balance) else None

    view = wait_for(settled, SETTLE_S, lambda: f"the pool split as its rule says:\n{logs()}", 1.0)
    assert all(a["capacity_hz"] > 0 for a in view["workers"].values())

    # `zstack query` on the robot, as docs/pool.md says to check: both workers live, the cameras
    # split between them, each camera's one server, their capacities, and no pool warning.
    def queried() -> dict[str, Any] | None:
        answer = _query(hosts, robot)
        if answer is None or answer.get("pool_warnings"):
            return None
        workers = answer.get("workers") or {}
        if sorted(w for w, m in workers.items() if m["live"]) != sorted(WORKERS):
            return None
        owner = {c: w for w in WORKERS for c in workers[w]["cameras"]}
        served = {c: m.get("served_by") for c, m in answer["cameras"].items()}
        cameras = sum(len(workers[w]["cameras"]) for w in WORKERS)
        return answer if cameras == len(view["cameras"]) and served == owner else None

    answer = wait_for(queried, 60, lambda: f"zstack query to show the pool:\n{logs()}", 1.0)
    assert all(f"{w}.capacity_hz" in answer["counters"] for w in WORKERS), answer["counters"]
    capacities = {w: round(a["capacity_hz"], 1) for w, a in view["workers"].items()}
    print(f"README pool: capacities {capacities}, split {view['serving']}")

    for proc in (sup_a, sup_b):
        proc.send_signal(signal.SIGINT)
    for name, proc in (("GPU box", sup_a), ("robot", sup_b)):
        assert proc.wait(timeout=30) == 0, f"{name}'s supervisor:\n{logs()}"


def test_the_readme_two_robots_on_one_gpu_box_run_as_written(tmp_path: Path) -> None:
    """docs/pool.md's several robots: gpu-box.toml's one worker serves the cameras of robot1.toml
    and of robot2.toml (robot1's "alike, with robot2 and 10.0.0.12"), each robot's detections
    on its own keys from that one worker, each robot's controller fresh on its camera."""
    gen = _network(SITE)
    hosts = next(gen)
    try:
        one = as_tested(named_block("robot1.toml").text, addresses={}, samples=())
        two = one.replace("robot1", "robot2").replace(ROBOT1_ADDRESS, ROBOT2_ADDRESS)
        texts = {"gpu": named_block("gpu-box.toml").text, "robot1": one, "robot2": two}
        configs = {}
        for role, text in texts.items():
            (tmp_path / role).mkdir()
            configs[role] = tmp_path / role / f"{role}.toml"
            configs[role].write_text(as_tested(text, addresses=SITE_ADDRESSES, samples=()))
            load_config(configs[role], environ={})
        prepare = ["-m", "deploy.zstack", "prepare", "--config", str(configs["gpu"])]
        prepared = hosts.call(hosts.ns["gpu"], prepare, 600)
        assert prepared.returncode == 0, prepared.stderr[-2000:]
        logs_at = {role: tmp_path / f"{role}.log" for role in configs}
        sups = {
            role: hosts.start(hosts.ns[role], ["-m", "deploy.zstack", "run", "--config",
                              str(configs[role])], logs_at[role].open("wb"))
            for role in ("robot1", "robot2", "gpu")
        }  # fmt: skip
        worker = f"detector_{load_config(configs['gpu'], environ={}).detector.worker_id}"

        def logs() -> str:
            return "\n".join(
                f"--- {r}:\n{p.read_text(errors='replace')[-3000:]}" for r, p in logs_at.items()
            )

        def served(role: str) -> dict[str, Any] | None:
            for name, proc in sups.items():
                if proc.poll() is not None:
                    pytest.fail(f"{name}'s supervisor exited ({proc.returncode}):\n{logs()}")
            cfg = load_config(configs[role], environ={})
            args = ["-m", "tests.integration.pool_view", "--config", str(configs[role])]
            done = hosts.call(hosts.ns[role], [*args, "--seconds", "4"], timeout=60)
            view = json.loads(done.stdout) if done.returncode == 0 else None
            if view is None or sorted(view["workers"]) != [worker] or not view["cameras"]:
                return None
            mine = {f"{cfg.stack.prefix}/{c}" for c in view["cameras"]}
            stale_sets = view["controller"]["stale_sets"]
            fresh = {c for c in view["cameras"] if any(c not in s for s in stale_sets)}
            ok = (
                mine <= set(view["serving"].get(worker, []))
                and all(view["publishers"].get(c) == 1 for c in view["cameras"])
                and fresh == set(view["cameras"])
                and cfg.stack.camera in view["controller"]["target_cameras"]
            )
            return view if ok else None

        for role in ("robot1", "robot2"):
            view = wait_for(lambda r=role: served(r), SETTLE_S,
                            lambda: f"{worker} serving every robot:\n{logs()}", 1.0)  # fmt: skip
        print(f"README robots: {worker} serves {view['serving'][worker]}")
        for proc in sups.values():
            proc.send_signal(signal.SIGINT)
        for name, proc in sups.items():
            assert proc.wait(timeout=30) == 0, f"{name}'s supervisor:\n{logs()}"
    finally:
        gen.close()

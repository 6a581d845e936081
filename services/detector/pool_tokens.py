"""A pool worker's own liveliness tokens (services/detector/membership.py): its member token
``<pool>/detector/pool/<worker id>`` and, for each camera it serves, a serving token
``<pool>/detector/serving/<worker>/<zenoh id>/<camera>``, which everyone's audit checks against
the membership (common/pool_audit.py). A worker that resigns for a stall withdraws both."""

from __future__ import annotations

import threading

from common.bus import Bus, Declared
from common.errors import StackError
from common.keys import Keys


class PoolTokens:
    """This worker's tokens in the pool. :attr:`lock` covers them and is held over their
    declaring and undeclaring, so that a resignation and a settle's serving tokens never
    interleave; no bus callback takes it. The methods that say "the caller holds the lock"
    are called inside ``with tokens.lock`` (the member takes it before its own lock when it
    needs both); the others take it themselves."""

    def __init__(self, bus: Bus, keys: Keys, me: str) -> None:
        self.lock = threading.Lock()
        self._bus = bus
        self._keys = keys
        self._me = me
        self._zid = bus.zid
        self._member: Declared | None = None
        self._serving: dict[str, Declared] = {}

    def members_if_free(self, timeout_s: float) -> list[str]:
        """The pool's member tokens alive now (asked for at most ``timeout_s``), once no
        worker of this name is found there: its member token or its announcement alive is a
        StackError (one line, exit 1), since two processes of one name would each serve every
        camera the rule gives the name. (One the query misses, two started at once, is the
        audit's ``name_twice`` warning.) The supervisor tries again after its backoff: a
        process just killed takes its tokens with its links."""
        keys, bus, me = self._keys, self._bus, self._me
        members = bus.live_tokens(keys.all_pool_members(), timeout_s)
        mine = keys.pool_member(me)
        held = [mine] if mine in members else []
        held += bus.live_tokens(keys.worker_announcements_of(me), timeout_s)
        if held:
            raise StackError(
                f"a detector worker named {me!r} is already in the pool ({held[0][:120]}): "
                "not starting a second; give each host its own detector.worker_id"
            )
        return members

    def declare_member(self) -> None:
        """Declare the member token (the caller holds the lock)."""
        self._member = self._bus.declare_token(self._keys.pool_member(self._me))

    def resign(self) -> None:
        """Withdraw the member token, then every serving token (the caller holds the lock)."""
        if self._member is not None:
            self._member.undeclare()
            self._member = None
        self._withdraw_serving()

    def sync_serving(self, serving: frozenset[str]) -> None:
        """One serving token for each camera of ``serving``, and none for another; nothing
        while the member token is withdrawn (resigned or closed: it serves nothing until it
        is back)."""
        with self.lock:
            if self._member is None:
                return
            for cam in [c for c in self._serving if c not in serving]:
                self._serving.pop(cam).undeclare()
            for cam in sorted(serving - self._serving.keys()):
                key = self._keys.pool_serving(self._me, self._zid, cam)
                self._serving[cam] = self._bus.declare_token(key)

    def serving(self) -> set[tuple[str, str, str]]:
        """(worker, zenoh id, camera) of each serving token held now."""
        with self.lock:
            return {(self._me, self._zid, cam) for cam in self._serving}

    def close(self) -> None:
        """Withdraw every serving token, then the member token."""
        with self.lock:
            self._withdraw_serving()
            if self._member is not None:
                self._member.undeclare()
                self._member = None

    def _withdraw_serving(self) -> None:
        for token in self._serving.values():
            token.undeclare()
        self._serving.clear()

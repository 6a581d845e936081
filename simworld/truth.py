"""What each camera shows of each person, frame by frame: the truth a tracker is scored
against (issue 42's evaluation). Pure.

:func:`visible_boxes` gives, for one camera's view of the world, each target that shows: its
scenario id, the box round the pixels of it that show (the colour image draws a person's
silhouette, a flat card's rectangle; what nearer things or a wall hide, and what the image's
edge cuts, does not show) and the share of it that shows. A detector's box should match the
first; a tracker that holds a person through an occlusion is scored on the frames where some
of them shows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simworld.depth import owners, placed_area
from simworld.render import CameraSpec
from simworld.world import World


@dataclass(frozen=True, slots=True)
class TruthBox:
    """One target as one camera shows it: ``target`` its scenario id, ``name`` its class,
    ``box`` (x0, y0, x1, y1) pixels round what shows (end-exclusive), ``visible`` the share
    of its whole drawing that shows (0..1)."""

    target: str
    name: str
    box: tuple[int, int, int, int]
    visible: float


def visible_boxes(world: World, spec: CameraSpec, min_visible: float = 0.0) -> list[TruthBox]:
    """Each target more than ``min_visible`` of which shows in ``spec``'s image of ``world``
    (:class:`TruthBox`), in the order of ``world.targets``."""
    owner, placed = owners(world, spec)
    out = []
    for k, p in enumerate(placed):
        if p.target is None or p.rect is None:
            continue
        ys, xs = np.nonzero(owner == k)
        if xs.size == 0:
            continue
        share = float(xs.size) / max(placed_area(p), 1.0)
        if share <= min_visible:
            continue
        tg = world.targets[p.target]
        box = (int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)
        out.append(TruthBox(tg.id, tg.name, box, min(share, 1.0)))
    out.sort(key=lambda b: [t.id for t in world.targets].index(b.target))
    return out

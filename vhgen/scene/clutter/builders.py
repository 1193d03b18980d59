"""The clutter builders: one function per kind that builds an item from unit primitives
(pure NumPy, see :mod:`vhgen.scene.meshkit`); its record in :mod:`vhgen.scene.clutter.kinds`
names it with everything else about the kind.

Every builder works in the item's own frame: x along the wall it stands against (centred
on x = 0), z from the wall (z = 0) into the room, y up from the floor, metres. Kinds that
may also stand free (a plant, boxes) are built the same way; placement turns them.
``p`` is the item's parameter dict (top-level sizes drawn from the scene stream within the
ranges of the kind's record, plus ``fill`` and ``seed``); ``g`` is a generator seeded with
``p["seed"]`` for the details (book widths, leaves): the parameters rebuild the item.
A builder may return explicit footprints for some groups (a door leaf at an angle, the
corridor behind a door); other groups get the box around their vertices.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from vhgen.geom.primitives import cylinder
from vhgen.scene.meshkit import BODY, FLOOR, OBJECT, WALL, Kit
from vhgen.scene.solids import rect

BOARD = 0.02  # shelf boards, cabinet sides


def _surfaces(kit: Kit, g: np.random.Generator, surf, fill: float, books: float) -> None:
    """Things standing on surfaces ``surf`` (S, 6) rows [x0, x1, z0, z1, y, max_h]: runs
    of upright books (a run is books with probability ``books``), book piles, boxes,
    cups, bottles, vases and balls, side by side along x (so they never overlap),
    covering about ``fill`` of each surface's length, at most ``max_h`` tall. Role
    OBJECT. All surfaces of an item at once: a few dozen array operations, not a Python
    loop per object."""
    sf = np.asarray(surf, np.float64).reshape(-1, 6)
    sf = sf[(sf[:, 1] - sf[:, 0] >= 0.05) & (sf[:, 3] - sf[:, 2] >= 0.05) & (sf[:, 5] >= 0.04)]
    if fill <= 0.0 or not len(sf):
        return
    x0, x1, z0, z1, y, max_h = (sf[:, k:k + 1] for k in range(6))
    depth = z1 - z0
    n_s, n_r = len(sf), int(np.ceil((x1 - x0).max() / 0.05)) + 1
    u = g.uniform(size=(10, n_s, n_r))
    is_books = u[0] < books
    nb = np.where(is_books, 3 + (u[1] * 13).astype(np.int64), 0)
    bw = g.uniform(0.015, 0.05, int(nb.sum()))
    cum = np.concatenate([[0.0], np.cumsum(bw)])
    ends = np.cumsum(nb.ravel())
    starts = ends - nb.ravel()
    width = np.where(is_books, (cum[ends] - cum[starts]).reshape(n_s, n_r), 0.06 + 0.24 * u[2])
    gap = width * (1.0 - fill) / max(fill, 0.05) * (0.3 + 1.4 * u[3]) + 0.005
    lead = u[4][:, :1] * 0.15 * (x1 - x0) * (1.0 - fill)
    step = np.cumsum(width + gap, axis=1)
    start = x0 + lead + np.concatenate([np.zeros((n_s, 1)), step[:, :-1]], axis=1)
    keep = start + width <= x1  # a prefix of each row: the runs grow along x
    sizes, centres = [], []
    # books: upright, their backs to the front edge, heights about the run's own
    run_keep = (keep & is_books).ravel()
    if run_keep.any():
        per_book = np.repeat(np.arange(n_s * n_r), nb.ravel())
        sel = run_keep[per_book]
        run = per_book[sel]
        w = bw[sel]
        x = (np.repeat(start.ravel(), nb.ravel())[sel]
             + (np.cumsum(bw) - bw)[sel] - cum[starts][run] + w / 2)
        s_of = run // n_r
        mh = max_h.ravel()[s_of]
        h = np.minimum(mh * (0.55 + 0.4 * u[8].ravel()[run]) * g.uniform(0.85, 1.0, len(run)), mh)
        dp = depth.ravel()[s_of]
        d = np.minimum(g.uniform(0.14, 0.24, len(run)), dp)
        z = z1.ravel()[s_of] - d / 2 - 0.03 * u[9].ravel()[run] * (dp > d + 0.03)
        sizes.append(np.column_stack([w - 0.001, h, d]))
        centres.append(np.column_stack([x, y.ravel()[s_of] + h / 2, z]))
    obj = (keep & ~is_books).ravel()
    if obj.any():
        s_of = np.flatnonzero(obj) // n_r
        w = width.ravel()[obj]
        dp = depth.ravel()[s_of]
        d = np.minimum(0.06 + 0.19 * u[6].ravel()[obj], dp)
        cx = start.ravel()[obj] + w / 2
        cz = z0.ravel()[s_of] + d / 2 + u[7].ravel()[obj] * (dp - d)
        base = y.ravel()[s_of]
        mh = max_h.ravel()[s_of]
        what, ua, ub = u[5].ravel()[obj], u[8].ravel()[obj], u[9].ravel()[obj]
        box = what < 0.3
        h = np.minimum(0.04 + 0.26 * ua, mh)
        sizes.append(np.column_stack([w, h, d])[box])
        centres.append(np.column_stack([cx, base + h / 2, cz])[box])
        pile = (what >= 0.3) & (what < 0.5)  # up to five books lying flat
        if pile.any():
            k = len(np.flatnonzero(pile))
            hs = g.uniform(0.015, 0.05, (k, 5))
            top = np.cumsum(hs, axis=1)
            ok = (np.arange(5) < 1 + (ub[pile] * 5).astype(np.int64)[:, None]) & (
                top <= mh[pile][:, None])
            shrink = g.uniform(0.8, 1.0, (k, 5, 2))
            rows = np.nonzero(ok)
            sizes.append(np.column_stack([w[pile][rows[0]] * shrink[rows][:, 0], hs[rows],
                                          d[pile][rows[0]] * shrink[rows][:, 1]]))
            centres.append(np.column_stack([cx[pile][rows[0]],
                                            base[pile][rows[0]] + top[rows] - hs[rows] / 2,
                                            cz[pile][rows[0]]]))
        cyl = (what >= 0.5) & (what < 0.85)  # a cup, a bottle, a vase
        r = np.minimum(w, d) / 2 * (0.6 + 0.4 * ua)
        kit.cylinders(r[cyl], np.minimum(0.06 + 0.29 * ub, mh)[cyl],
                      np.column_stack([cx, base, cz])[cyl], OBJECT)
        ball = what >= 0.85
        rb = np.minimum(np.minimum(w, d), mh) / 2 * (0.7 + 0.3 * ua)
        kit.spheres(np.repeat(rb[ball, None], 3, 1),
                    np.column_stack([cx, base + rb, cz])[ball], OBJECT)
    if sizes:
        kit.boxes(np.concatenate(sizes), np.concatenate(centres), OBJECT)


def bookcase(kit: Kit, p: dict, g: np.random.Generator) -> None:
    w, d, h, t = p["w"], p["d"], p["h"], BOARD
    levels = max(2, round((h - 0.1) / p["spacing"]))
    ys = 0.08 + np.arange(levels + 1) * (h - 0.08 - t) / levels  # board bottoms
    kit.boxes([[t, h, d], [t, h, d], [w - 2 * t, 0.08, d]],
              [[-w / 2 + t / 2, h / 2, d / 2], [w / 2 - t / 2, h / 2, d / 2],
               [0, 0.04, d / 2]], BODY)
    kit.boxes(np.tile([w - 2 * t, t, d], (levels, 1)),
              np.column_stack([np.zeros(levels), ys[1:] + t / 2, np.full(levels, d / 2)]),
              BODY)
    back = p["back"] < 0.7
    if back:
        kit.box([w - 2 * t, h - 0.08, 0.01], [0, 0.04 + h / 2, 0.005], BODY)
    bottoms = np.concatenate([[0.08], ys[1:-1] + t])
    _surfaces(kit, g, np.column_stack([
        np.full(levels, -w / 2 + t), np.full(levels, w / 2 - t),
        np.full(levels, 0.012 if back else 0.0), np.full(levels, d - 0.01), bottoms,
        ys[1:] - bottoms - 0.015]), p["fill"], 0.8)


def shelf(kit: Kit, p: dict, g: np.random.Generator) -> None:
    w, d, t = p["w"], p["d"], BOARD
    n = int(p["boards"])
    y = p["y"] + np.arange(n) * p["spacing"]
    kit.boxes(np.tile([w, t, d], (n, 1)), np.column_stack([np.zeros(n), y + t / 2,
                                                            np.full(n, d / 2)]), BODY)
    kit.boxes(np.tile([0.02, 0.12, d * 0.8], (2 * n, 1)),
              np.column_stack([np.tile([-w / 2 + 0.08, w / 2 - 0.08], n), np.repeat(y - 0.06, 2),
                               np.full(2 * n, d * 0.4)]), BODY)
    _surfaces(kit, g, np.column_stack([np.full(n, -w / 2 + 0.01), np.full(n, w / 2 - 0.01),
                                       np.zeros(n), np.full(n, d - 0.01), y + t,
                                       np.full(n, p["spacing"] - t - 0.03)]), p["fill"], 0.5)


def cabinet(kit: Kit, p: dict, g: np.random.Generator) -> None:
    w, d, h = p["w"], p["d"], p["h"]
    kit.box([w, h - 0.06, d], [0, 0.06 + (h - 0.06) / 2, d / 2], BODY)
    kit.box([w - 0.06, 0.06, d - 0.04], [0, 0.03, d / 2 - 0.02], BODY)  # recessed plinth
    n = int(p["doors"])
    dw = w / n
    xs = -w / 2 + dw * (np.arange(n) + 0.5)
    kit.boxes(np.tile([dw - 0.006, h - 0.1, 0.012], (n, 1)),
              np.column_stack([xs, np.full(n, 0.06 + (h - 0.06) / 2), np.full(n, d + 0.006)]),
              BODY)
    kit.boxes(np.tile([0.02, 0.1, 0.025], (n, 1)),
              np.column_stack([xs + dw * 0.35, np.full(n, h - 0.15), np.full(n, d + 0.024)]),
              BODY)
    _surfaces(kit, g, [-w / 2 + 0.02, w / 2 - 0.02, 0.02, d - 0.02, h, 0.45], p["fill"], 0.3)


def _office_chair(kit: Kit, g: np.random.Generator, cx: float, cz: float, yaw: float) -> None:
    seat = g.uniform(0.42, 0.52)
    back_h = g.uniform(0.35, 0.55)
    c, s = math.cos(yaw), math.sin(yaw)

    def at(x: float, z: float) -> list[float]:  # chair-local (x, z) to item-local
        return [cx + c * x + s * z, cz - s * x + c * z]

    kit.box([0.46, 0.07, 0.46], [at(0, 0)[0], seat - 0.035, at(0, 0)[1]], BODY, yaw=yaw)
    bx, bz = at(0, 0.22)
    kit.box([0.42, back_h, 0.05], [bx, seat + 0.05 + back_h / 2, bz], BODY, yaw=yaw)
    kit.tubes([[cx, 0.1, cz]], [[cx, seat - 0.07, cz]], 0.025, BODY)
    a = yaw + np.arange(5) * 2 * np.pi / 5 + g.uniform(0, 2 * np.pi)
    tips = np.column_stack([cx + 0.3 * np.cos(a), np.full(5, 0.05), cz + 0.3 * np.sin(a)])
    kit.tubes(np.tile([cx, 0.1, cz], (5, 1)), tips, 0.018, BODY, sections=4)
    kit.spheres(np.full((5, 3), 0.025), tips - np.array([0, 0.025, 0]), BODY)


def chair(kit: Kit, p: dict, g: np.random.Generator) -> None:
    """A chair standing free, its back to -z (to the wall, if it stands against one;
    placement turns it): below 0.65 of ``style`` a swivel chair whose back, ``back`` tall,
    wraps round the sitter by ``curve`` radians a side and leans back by ``recline``, with
    arms if ``arms`` < 0.5; above, an upholstered armchair."""
    w, seat, back = p["w"], p["seat"], p["back"]
    arms = p["arms"] < 0.5
    if p["style"] >= 0.65:  # an upholstered armchair: seat, back and arms as blocks
        d, back_h, arm = w + 0.2, back * 0.8, 0.16
        wide = w + 2 * arm
        kit.box([wide, seat - 0.1, d], [0, 0.1 + (seat - 0.1) / 2, 0], BODY)
        kit.boxes(np.tile([0.05, 0.1, 0.05], (4, 1)),
                  [[sx * (wide / 2 - 0.05), 0.05, sz * (d / 2 - 0.05)] for sx in (-1, 1)
                   for sz in (-1, 1)], BODY)
        kit.box([w, 0.1, d - 0.2], [0, seat + 0.05, 0.1], BODY)  # the cushion
        kit.box([wide, back_h + 0.1, 0.2], [0, seat + back_h / 2, 0.1 - d / 2], BODY)
        ah = seat + g.uniform(0.12, 0.25) - 0.1
        kit.boxes([[arm, ah, d - 0.2]] * 2,
                  [[sx * (w / 2 + arm / 2), 0.1 + ah / 2, 0.1] for sx in (-1, 1)], BODY)
        return
    # the swivel chair: seat, a back of stacked rows (each a middle panel and two wings)
    kit.box([w, 0.08, w * 0.95], [0, seat - 0.04, 0], BODY)
    rows = 4
    rh = back / rows
    wing = w * 0.3
    for k in range(rows):
        z = -w * 0.42 - (k + 0.5) * rh * math.tan(p["recline"])
        y = seat + 0.06 + (k + 0.5) * rh
        mid = w - 2 * wing
        kit.box([mid, rh + 0.01, 0.06], [0, y, z], BODY)
        a = p["curve"]
        for sx in (-1, 1):
            cx = sx * (mid / 2 + math.cos(a) * wing / 2)
            kit.box([wing, rh + 0.01, 0.06], [cx, y, z + math.sin(a) * wing / 2], BODY,
                    yaw=float(-sx * a))
    top = seat + 0.06 + back
    if g.uniform() < 0.3:  # a headrest
        hz = -w * 0.42 - back * math.tan(p["recline"]) - 0.02
        kit.box([w * 0.5, 0.16, 0.08], [0, top + 0.1, hz], BODY)
    if arms:
        for sx in (-1, 1):
            x = sx * (w / 2 + 0.03)
            kit.box([0.06, 0.04, w * 0.5], [x, seat + 0.22, 0.0], BODY)
            kit.tubes([[x, seat - 0.04, 0.05]], [[x, seat + 0.2, 0.05]], 0.02, BODY,
                      sections=4)
    kit.tubes([[0, 0.1, 0]], [[0, seat - 0.08, 0]], 0.025, BODY)
    a = np.arange(5) * 2 * np.pi / 5 + g.uniform(0, 2 * np.pi)
    tips = np.column_stack([0.3 * np.cos(a), np.full(5, 0.05), 0.3 * np.sin(a)])
    kit.tubes(np.tile([0, 0.1, 0], (5, 1)), tips, 0.018, BODY, sections=4)
    kit.spheres(np.full((5, 3), 0.025), tips - np.array([0, 0.025, 0]), BODY)


def coat_stand(kit: Kit, p: dict, g: np.random.Generator) -> None:
    """A pole on a round foot with hooks near its top, and up to three coats (a long
    soft body, shoulders), bags or hats hanging from them."""
    h = p["height"]
    kit.cylinders([g.uniform(0.18, 0.25)], [0.03], [[0, 0, 0]], BODY, sections=16)
    kit.tubes([[0, 0.03, 0]], [[0, h, 0]], 0.02, BODY)
    n = int(p["hooks"])
    az = np.arange(n) * 2 * np.pi / n + g.uniform(0, 2 * np.pi)
    hook = np.column_stack([0.14 * np.cos(az), np.full(n, h - 0.1), 0.14 * np.sin(az)])
    kit.tubes(np.tile([0, h - 0.18, 0], (n, 1)), hook, 0.008, BODY, sections=4)
    for k in g.permutation(n)[:int(p["coats"])]:
        out = np.array([np.cos(az[k]), 0.0, np.sin(az[k])])
        what = g.uniform()
        if what < 0.65:  # a coat: shoulders at the hook, a body hanging down, sleeves
            ln = p["coat_len"] * g.uniform(0.85, 1.15)
            sw, th = g.uniform(0.18, 0.24), g.uniform(0.06, 0.12)
            c = hook[k] + out * (th + 0.03)
            yaw = float(np.arctan2(out[0], out[2]))
            kit.box([2 * sw, ln, 2 * th], [c[0], h - 0.12 - ln / 2, c[2]], BODY, yaw=yaw)
            kit.spheres([[sw, 0.07, th]], [[c[0], h - 0.14, c[2]]], BODY)
        elif what < 0.85:  # a bag on its strap
            bh = g.uniform(0.25, 0.4)
            c = hook[k] + out * 0.1
            kit.tubes([hook[k]], [[c[0], h - 0.35, c[2]]], 0.008, BODY, sections=4)
            kit.spheres([[0.16, bh / 2, 0.08]], [[c[0], h - 0.35 - bh / 2, c[2]]], BODY)
        else:  # a hat on the hook
            kit.cylinders([0.1], [0.1], [hook[k] + out * 0.05], BODY, sections=12,
                          top_ratio=0.8)


def desk(kit: Kit, p: dict, g: np.random.Generator) -> None:
    w, d, h = p["w"], p["d"], p["h"]
    kit.box([w, 0.03, d], [0, h - 0.015, d / 2], BODY)
    if g.uniform() < 0.5:  # a drawer unit on one side, a panel on the other
        side = 1 if g.uniform() < 0.5 else -1
        kit.box([0.4, h - 0.03, d - 0.05], [side * (w / 2 - 0.2), (h - 0.03) / 2, d / 2], BODY)
        kit.box([0.03, h - 0.03, d - 0.05], [-side * (w / 2 - 0.015), (h - 0.03) / 2, d / 2],
                BODY)
    else:
        kit.boxes([[0.03, h - 0.03, d - 0.05]] * 2,
                  [[-w / 2 + 0.015, (h - 0.03) / 2, d / 2], [w / 2 - 0.015, (h - 0.03) / 2,
                                                              d / 2]], BODY)
    mw = min(p["monitor"], w - 0.3)
    mh = mw * g.uniform(0.56, 0.65)
    mx = g.uniform(-0.2, 0.2) * (w - mw)
    mz = g.uniform(0.1, 0.2)
    lift = g.uniform(0.08, 0.15)
    kit.box([mw, mh, 0.03], [mx, h + lift + mh / 2, mz], BODY)
    kit.box([0.05, lift + 0.02, 0.03], [mx, h + (lift + 0.02) / 2, mz - 0.03], BODY)
    kit.box([0.24, 0.015, 0.18], [mx, h + 0.0075, mz], BODY)
    kz = min(mz + g.uniform(0.2, 0.3), d - 0.09)
    kit.box([0.44, 0.025, 0.14], [mx + g.uniform(-0.05, 0.05), h + 0.0125, kz], BODY)
    left, right = mx - mw / 2 - 0.05, mx + mw / 2 + 0.05
    _surfaces(kit, g, [[-w / 2 + 0.02, left, 0.02, d - 0.03, h, 0.4],
                       [right, w / 2 - 0.02, 0.02, d - 0.03, h, 0.4]], p["fill"], 0.2)
    if p["chair"] < 0.6:
        kit.group = 1
        _office_chair(kit, g, g.uniform(-0.2, 0.2) * w, d + 0.36 + g.uniform(0.0, 0.15),
                      g.uniform(-0.5, 0.5))


def tv(kit: Kit, p: dict, g: np.random.Generator) -> None:
    w, d, h = p["w"], p["d"], p["h"]
    kit.box([w, h, d], [0, h / 2, d / 2], BODY)
    sw = min(p["screen"], w)
    sh = sw * 0.58
    sx = g.uniform(-0.1, 0.1) * (w - sw)
    if g.uniform() < 0.3:  # on the wall above the stand
        bottom = h + g.uniform(0.15, 0.4)
        kit.box([sw, sh, 0.05], [sx, bottom + sh / 2, 0.03], BODY)
        _surfaces(kit, g, [-w / 2 + 0.02, w / 2 - 0.02, 0.06, d - 0.02, h, 0.35], p["fill"],
                  0.2)
        return
    bottom = h + g.uniform(0.05, 0.1)
    kit.box([sw, sh, 0.05], [sx, bottom + sh / 2, d / 2], BODY)
    kit.box([0.06, bottom - h, 0.04], [sx, h + (bottom - h) / 2, d / 2], BODY)
    kit.box([0.35, 0.015, 0.22], [sx, h + 0.0075, d / 2], BODY)
    _surfaces(kit, g, [[-w / 2 + 0.02, sx - 0.2, 0.02, d - 0.02, h, 0.35],
                       [sx + 0.2, w / 2 - 0.02, 0.02, d - 0.02, h, 0.35]], p["fill"], 0.2)


def table(kit: Kit, p: dict, g: np.random.Generator) -> None:
    w, d, h = p["w"], p["d"], p["h"]
    kit.box([w, 0.04, d], [0, h - 0.02, d / 2], BODY)
    x, z = w / 2 - 0.05, d / 2 - 0.05
    kit.boxes(np.tile([0.06, h - 0.04, 0.06], (4, 1)),
              [[sx * x, (h - 0.04) / 2, d / 2 + sz * z] for sx in (-1, 1) for sz in (-1, 1)],
              BODY)
    _surfaces(kit, g, [-w / 2 + 0.03, w / 2 - 0.03, 0.03, d - 0.03, h, 0.35], p["fill"], 0.15)


def plant(kit: Kit, p: dict, g: np.random.Generator) -> None:
    """A pot, a trunk, branches and leaves: thin structures the sensor breaks up."""
    r, ph, top = p["pot_r"], p["pot_h"], p["height"]
    kit.cylinders([r], [ph], [[0, 0, 0]], BODY, sections=16, top_ratio=1.25)
    trunk_top = np.array([g.uniform(-0.05, 0.05), top * 0.85, g.uniform(-0.05, 0.05)])
    kit.tubes([[0, ph * 0.8, 0]], [trunk_top], g.uniform(0.01, 0.025), BODY)
    nb = int(p["branches"])
    t = g.uniform(0.3, 0.95, nb)
    starts = np.array([0, ph * 0.8, 0]) + t[:, None] * (trunk_top - np.array([0, ph * 0.8, 0]))
    az = g.uniform(0, 2 * np.pi, nb)
    el = g.uniform(np.deg2rad(15), np.deg2rad(70), nb)
    length = g.uniform(0.15, 0.5, nb) * min(1.0, top / 1.2)
    dirs = np.column_stack([np.cos(el) * np.cos(az), np.sin(el), np.cos(el) * np.sin(az)])
    ends = starts + dirs * length[:, None]
    kit.tubes(starts, ends, g.uniform(0.006, 0.012, nb), BODY, sections=4)
    # leaves along each branch and round the trunk's top
    nl = int(p["leaves"])
    anchors_a = np.concatenate([starts, np.tile(trunk_top, (1, 1))])
    anchors_b = np.concatenate([ends, [trunk_top + np.array([0, 0.05, 0])]])
    k = len(anchors_a)
    s = g.uniform(0.2, 1.0, (k, nl))
    base = anchors_a[:, None] + s[..., None] * (anchors_b - anchors_a)[:, None]
    base = base.reshape(-1, 3)
    n = len(base)
    laz = g.uniform(0, 2 * np.pi, n)
    lel = g.uniform(-0.6, 0.5, n)  # mostly out and somewhat down, as leaves droop
    ldir = np.column_stack([np.cos(lel) * np.cos(laz), np.sin(lel), np.cos(lel) * np.sin(laz)])
    ll = p["leaf"] * g.uniform(0.6, 1.4, n)
    base[:, 1] = np.maximum(base[:, 1], ph + ll)  # no leaf reaches into the floor
    kit.leaves(base, ldir, ll, g.uniform(-0.8, 0.8, n), BODY)


def stairs(kit: Kit, p: dict, g: np.random.Generator) -> None:
    """A straight flight along the wall: open treads on stringers with a railing of thin
    balusters, or a closed flight."""
    n, rise, run, width = int(p["steps"]), p["rise"], p["run"], p["width"]
    length = n * run
    sgn = 1.0 if p["dir"] < 0.5 else -1.0
    k = np.arange(1, n + 1)
    xs = sgn * (-length / 2 + (k - 0.5) * run)
    if p["open"] < 0.6:
        thick = 0.04
        kit.boxes(np.tile([run + 0.02, thick, width], (n, 1)),
                  np.column_stack([xs, k * rise - thick / 2, np.full(n, width / 2)]), BODY)
        x0, x1 = sgn * -length / 2, sgn * length / 2
        for z in (0.04, width - 0.04):
            kit.tubes([[x0, 0.035, z]], [[x1, n * rise - 0.05, z]], 0.035, BODY, sections=4)
    else:
        kit.boxes(np.column_stack([np.full(n, run), k * rise, np.full(n, width)]),
                  np.column_stack([xs, k * rise / 2, np.full(n, width / 2)]), BODY)
    # the railing on the room side
    zr = width - 0.03
    per = 2 if run > 0.27 else 1
    bx = (sgn * (-length / 2 + (np.arange(n * per) + 0.5) * run / per))
    by = (np.arange(n * per) // per + 1) * rise
    rail = 0.9
    kit.tubes(np.column_stack([bx, by, np.full(len(bx), zr)]),
              np.column_stack([bx, by + rail, np.full(len(bx), zr)]),
              g.uniform(0.01, 0.015), BODY, sections=4)
    kit.tubes([[bx[0], by[0] + rail, zr]], [[bx[-1], by[-1] + rail, zr]], 0.025, BODY)


def lamp(kit: Kit, p: dict, g: np.random.Generator) -> None:
    h, r, sh = p["height"], p["shade_r"], p["shade_h"]
    kit.cylinders([g.uniform(0.12, 0.18)], [0.03], [[0, 0, 0]], BODY, sections=16)
    kit.tubes([[0, 0.03, 0]], [[0, h, 0]], 0.012, BODY)
    taper = round(p["taper"] * 20) / 20  # a few cached frusta, not one per lamp
    t = np.zeros((1, 3, 4))
    t[0, 0, 0], t[0, 1, 1], t[0, 2, 2] = r, sh, r
    t[0, :, 3] = [0, h - sh * 0.6, 0]
    kit.add(cylinder(16, taper, False), t, BODY)


def radiator(kit: Kit, p: dict, g: np.random.Generator) -> None:
    w, h, y, d = p["w"], p["h"], p["y"], p["d"]
    n = max(3, int(w / p["pitch"]))
    xs = -w / 2 + (np.arange(n) + 0.5) * w / n
    z = 0.04 + d / 2
    kit.boxes(np.tile([min(0.015, w / n * 0.5), h, d], (n, 1)),
              np.column_stack([xs, np.full(n, y + h / 2), np.full(n, z)]), BODY)
    kit.tubes([[-w / 2, y + 0.03, z], [-w / 2, y + h - 0.03, z]],
              [[w / 2, y + 0.03, z], [w / 2, y + h - 0.03, z]], 0.015, BODY)
    kit.boxes([[0.03, 0.04, 0.04]] * 2, [[-w / 4, y + h - 0.1, 0.02], [w / 4, y + h - 0.1,
                                                                       0.02]], BODY)


def window(kit: Kit, p: dict, g: np.random.Generator) -> None:
    """Glass (role BODY: the window's class, which gives no return) in a frame and over a
    sill that belong to the wall (role WALL)."""
    w, h, y0, f = p["w"], p["h"], p["sill"], p["frame"]
    kit.box([w - 2 * f, h - 2 * f, 0.005], [0, y0 + h / 2, 0.012], BODY)
    kit.boxes([[f, h, 0.05], [f, h, 0.05], [w - 2 * f, f, 0.05], [w - 2 * f, f, 0.05]],
              [[-w / 2 + f / 2, y0 + h / 2, 0.025], [w / 2 - f / 2, y0 + h / 2, 0.025],
               [0, y0 + f / 2, 0.025], [0, y0 + h - f / 2, 0.025]], WALL)
    m = int(p["mullions"])
    if m:
        xs = -w / 2 + f + (np.arange(m) + 1) * (w - 2 * f) / (m + 1)
        kit.boxes(np.tile([0.04, h - 2 * f, 0.04], (m, 1)),
                  np.column_stack([xs, np.full(m, y0 + h / 2), np.full(m, 0.025)]), WALL)
    kit.box([w + 0.1, 0.03, p["sill_d"]], [0, y0 - 0.015, p["sill_d"] / 2], WALL)


def curtain(kit: Kit, p: dict, g: np.random.Generator) -> None:
    """A pleated drape from a rod: a folded open surface (role BODY)."""
    w, top, bottom = p["w"], p["top"], p["bottom"]
    per, amp = p["period"], p["amplitude"]
    nx = max(4, int(math.ceil(w / (per / 6)))) + 1
    x = np.linspace(-w / 2, w / 2, nx)
    phase = g.uniform(0, 2 * np.pi)
    wave = 1.0 + np.sin(2 * np.pi * x / per + phase)
    rows = np.array([top, (top + bottom) / 2, bottom])
    flare = np.array([1.0, 1.15, 1.3])  # folds open towards the hem
    z = 0.06 + amp * wave[None, :] * flare[:, None]
    v = np.stack([np.broadcast_to(x, z.shape), np.broadcast_to(rows[:, None], z.shape), z],
                 -1).reshape(-1, 3)
    i = np.arange(nx - 1)
    faces = []
    for r in range(2):
        a, b = r * nx + i, (r + 1) * nx + i
        faces += [np.column_stack([a, b, a + 1]), np.column_stack([a + 1, b, b + 1])]
    kit.mesh(v, np.concatenate(faces), BODY)
    kit.tubes([[-w / 2 - 0.08, top + 0.03, 0.06]], [[w / 2 + 0.08, top + 0.03, 0.06]], 0.012,
              BODY)


def door(kit: Kit, p: dict, g: np.random.Generator) -> list:
    """A door in the wall: a frame round an opening the layout cuts in the wall, the leaf
    open at ``angle_deg`` (0 = shut) into the room, and the corridor behind (floor, walls
    and ceiling: the building's roles)."""
    w, h = p["w"], p["h"]
    fw, reveal = 0.06, 0.12
    # the frame's trim on the room side; its lining in the wall goes with the corridor
    trim = [[fw, h + fw], [fw, h + fw], [w + 2 * fw, fw]]
    at = [[-w / 2 - fw / 2, (h + fw) / 2], [w / 2 + fw / 2, (h + fw) / 2], [0, h + fw / 2]]
    kit.boxes([[a, b, 0.02] for a, b in trim], [[x, y, 0.01] for x, y in at], BODY)
    side = 1.0 if p["hinge"] < 0.5 else -1.0
    a = np.deg2rad(p["angle_deg"])
    hinge = np.array([side * w / 2, 0.04])
    d = np.array([-side * np.cos(a), np.sin(a)])  # from the hinge along the leaf
    n = np.array([-d[1], d[0]])
    lw = w - 0.01
    mid = hinge + d * lw / 2
    kit.group = 1
    kit.box([lw, h - 0.01, 0.04], [mid[0], (h - 0.01) / 2, mid[1]], BODY,
            yaw=float(np.arctan2(-d[1], d[0])))
    leaf = np.array([hinge + 0.02 * n, hinge + d * lw + 0.02 * n, hinge + d * lw - 0.02 * n,
                     hinge - 0.02 * n])
    e0, e1 = leaf[1] - leaf[0], leaf[2] - leaf[1]
    if e0[0] * e1[1] - e0[1] * e1[0] < 0:  # counter-clockwise in (x, z)
        leaf = leaf[::-1]
    kit.group = 2
    kit.boxes([[a, b, reveal] for a, b in trim], [[x, y, -reveal / 2] for x, y in at], BODY)
    cd, cw = p["corridor_d"], w + p["corridor_w"]
    ch = h + fw + 0.05 + 0.3 * g.uniform()
    x0, x1, z0 = -cw / 2, cw / 2, -reveal - cd
    quads = np.array([
        [[x0, 0, -reveal], [x1, 0, -reveal], [x1, 0, z0], [x0, 0, z0]],
        [[x0, 0, z0], [x1, 0, z0], [x1, ch, z0], [x0, ch, z0]],
        [[x0, 0, -reveal], [x0, 0, z0], [x0, ch, z0], [x0, ch, -reveal]],
        [[x1, 0, -reveal], [x1, 0, z0], [x1, ch, z0], [x1, ch, -reveal]],
        [[x0, ch, -reveal], [x1, ch, -reveal], [x1, ch, z0], [x0, ch, z0]],
    ])
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    kit.mesh(quads[:1].reshape(-1, 3), tri, FLOOR)
    kit.mesh(quads[1:].reshape(-1, 3), np.concatenate([tri + 4 * k for k in range(4)]), WALL)
    # the floor of the reveal, between the room's floor and the corridor's
    kit.mesh(np.array([[-w / 2, 0, 0.0], [w / 2, 0, 0.0], [w / 2, 0, -reveal],
                       [-w / 2, 0, -reveal]]), tri, FLOOR)
    return [(rect(-w / 2 - fw, w / 2 + fw, 0.0, 0.02), 0.0, h + fw, True),
            (leaf, 0.0, h, True),
            (rect(min(x0, -w / 2 - fw), max(x1, w / 2 + fw), z0, 0.0), 0.0, ch, False)]


def door_opening(p: Mapping[str, float]) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) of the hole a door of parameters ``p`` cuts in its wall."""
    return (-p["w"] / 2, p["w"] / 2, 0.0, p["h"])


def boxes(kit: Kit, p: dict, g: np.random.Generator) -> None:
    w, d, h = p["w"], p["d"], p["h"]
    y = 0.0
    for k in range(int(p["count"])):
        s = 1.0 if k == 0 else g.uniform(0.6, 0.95)
        bw, bd, bh = w * s, d * s, h * g.uniform(0.7, 1.0)
        off = 0.0 if k == 0 else g.uniform(-0.5, 0.5) * (w - bw)
        kit.box([bw, bh, bd], [off, y + bh / 2, d / 2 + (0.0 if k == 0 else g.uniform(-0.5, 0.5)
                                                         * (d - bd))], BODY)
        y += bh


def bag(kit: Kit, p: dict, g: np.random.Generator) -> None:
    w, h, d = p["w"], p["h"], p["d"]
    if g.uniform() < 0.5:  # a soft bag
        kit.spheres([[w / 2, h / 2, d / 2]], [[0, h / 2, d / 2]], BODY)
    else:  # a backpack or a case
        kit.box([w, h * 0.85, d], [0, h * 0.425, d / 2], BODY)
        kit.spheres([[w / 2 * 0.95, h * 0.15, d / 2 * 0.95]], [[0, h * 0.85, d / 2]], BODY)
    if p["handles"] < 0.6:
        top = h
        pts = np.array([[-w * 0.2, top * 0.95, d / 2], [-w * 0.1, top + 0.1, d / 2],
                        [w * 0.1, top + 0.1, d / 2], [w * 0.2, top * 0.95, d / 2]])
        kit.tubes(pts[:-1], pts[1:], 0.01, BODY, sections=4)


def objects(kit: Kit, p: dict, g: np.random.Generator) -> None:
    """Small things on the floor (shoes, balls, bottles, toys), one per cell of a grid
    over the patch so that none overlap. Role OBJECT."""
    w, d, n = p["w"], p["d"], int(p["count"])
    cols = max(1, int(math.ceil(math.sqrt(n * w / d))))
    rows = int(math.ceil(n / cols))
    cw, cd = w / cols, d / rows
    cells = g.permutation(cols * rows)[:n]
    bs, bc, cr, chh, cb, sr, sc = [], [], [], [], [], [], []
    for c in cells:
        x0, z0 = -w / 2 + (c % cols) * cw, (c // cols) * cd
        cx, cz = x0 + cw / 2, z0 + cd / 2
        size = min(cw, cd) * g.uniform(0.5, 0.9)
        what = g.uniform()
        if what < 0.4:
            sx, sz = size, size * g.uniform(0.35, 1.0)
            hh = g.uniform(0.05, 0.2)
            bs.append([sx, hh, sz])
            bc.append([cx, hh / 2, cz])
        elif what < 0.7:
            r = size / 2
            cr.append(r * g.uniform(0.3, 1.0))
            chh.append(g.uniform(0.08, 0.35))
            cb.append([cx, 0.0, cz])
        else:
            r = min(size / 2, 0.15)
            sr.append([r, r, r])
            sc.append([cx, r, cz])
    kit.boxes(bs, bc, OBJECT)
    kit.cylinders(cr, chh, cb, OBJECT)
    kit.spheres(sr, sc, OBJECT)


def picture(kit: Kit, p: dict, g: np.random.Generator) -> None:
    kit.box([p["w"], p["h"], p["t"]], [0, p["y"], p["t"] / 2 + 0.003], BODY)

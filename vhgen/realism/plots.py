"""One PNG with a panel per statistic: the real frames against each set of vhgen frames
(matplotlib, imported inside the function; Agg backend, no display)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from vhgen.realism.compare import noise_curve
from vhgen.realism.stats import FrameStats


def _cat(stats: Sequence[FrameStats], name: str) -> np.ndarray:
    parts = [np.atleast_1d(np.asarray(getattr(s, name), np.float64)) for s in stats]
    return np.concatenate(parts) if parts else np.zeros(0)


def plot_realism(path: str | Path, sets: Mapping[str, Sequence[FrameStats]]) -> Path:
    """Write the comparison figure; ``sets`` maps a name (the real frames first) to the
    frame statistics of that set."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(3, 3, figsize=(16, 13))
    ax = ax.ravel()
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    names = list(sets)
    step_top = 1.0
    for k, (name, st) in enumerate(sets.items()):
        c = colors[k % len(colors)]
        ax[0].hist(_cat(st, "valid_fraction"), bins=20, range=(0, 1), alpha=0.5, color=c,
                   density=True, label=name)
        ax[1].hist(_cat(st, "depth_m"), bins=60, range=(0, 10), density=True, alpha=0.5,
                   color=c, histtype="stepfilled", label=name)
        far = _cat(st, "farthest_m")
        ax[1].plot(far, np.full_like(far, 0.02 + 0.02 * k), "|", color=c, ms=12)
        for side, (jn, wn, mark) in enumerate((("shadow_jump", "shadow_width", "o"),
                                               ("other_jump", "other_width", "x"))):
            j, w = _cat(st, jn), _cat(st, wn)
            sel = np.arange(len(j))[:: max(1, len(j) // 1500)]
            ax[2].plot(j[sel], w[sel], mark, ms=2, alpha=0.3, color=c,
                       label=f"{name} {'shadow' if side == 0 else 'other'} side")
        holes = _cat(st, "hole_areas")
        ax[3].hist(np.log10(np.maximum(holes, 1)), bins=30, range=(0, 5.5), density=True,
                   alpha=0.5, color=c, label=name)
        ax[4].bar(k, len(_cat(st, "speckle_areas")) / max(len(st), 1), color=c, label=name)
        z, sig, _ = noise_curve(st)
        ax[5].plot(z, sig, "o-", color=c, label=name)
        pz, ps = _cat(st, "patch_depth_m"), _cat(st, "patch_step_mm")
        ok = np.isfinite(ps)
        sel = np.flatnonzero(ok)[:: max(1, int(ok.sum()) // 3000)]
        ax[6].plot(pz[sel], ps[sel], ".", ms=2, alpha=0.4, color=c, label=name)
        if ok.any():  # a few patches straddle two surfaces: keep the axis on the steps
            step_top = max(step_top, float(np.percentile(ps[ok], 99)))
        b = np.mean(np.stack([s.border_px for s in st]), 0) if st else np.zeros(4)
        ax[7].bar(np.arange(4) + 0.8 * k / len(names), b, width=0.8 / len(names), color=c,
                  label=name)
        holes_pf = [len(s.hole_areas) for s in st]
        ax[8].hist(holes_pf, bins=20, alpha=0.5, color=c, density=True, label=name)
    titles = ["valid-pixel fraction per frame", "depth of valid pixels (m); ticks: p99.9",
              "hole width (px) beside edges vs 1/z_near - 1/z_far (1/m)",
              "hole blob size (log10 px), density", "speckles (valid islands <= 200 px) per frame",
              "axial noise on planar patches (mm) vs depth (m)",
              "quantisation step in patches (mm) vs depth (m)",
              "border band (px): left, right, top, bottom", "hole blobs per frame"]
    for a, t in zip(ax, titles, strict=True):
        a.set_title(t, fontsize=10)
        a.legend(fontsize=7)
    ax[2].set_xlim(0, 1.5)
    ax[6].set_ylim(0, step_top * 1.1)
    ax[2].set_ylim(0, 60)
    ax[4].set_xticks(range(len(names)), names, fontsize=7, rotation=15)
    ax[7].set_xticks(range(4), ["left", "right", "top", "bottom"])
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=80)
    plt.close(fig)
    return out

"""A frame the GL sensor left in a staging buffer, decoded in one pass (numba).

A worker that sends frames in batches (:meth:`vhgen.pipeline.frames.FrameGenerator.frames`)
reads back, per frame, the sensor's output words (:meth:`GLSensorModel.queue_target`: the
encoded depth and raw value, the flags, the disparity, the packed ids) after the
renderer's targets. :func:`vhgen.render.sensor_gl.sensor_output` makes the sensor's full
:class:`~vhgen.sensor.simulator.SensorOutput` of such words (every hole mask, the
disparity as float64), which a frame then unpacks: some fifteen passes over the image.
:func:`decode` makes what a frame keeps (depth, raw, labels, instances, classes, the
count of each hole cause and of valid pixels, and the instances of the rendered view for
the joints' visibility) in one, with the same values: the batch tests compare the stores
of frames one by one and in batches, :mod:`tests.render.test_frame_words` the two
decodings on made-up words.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from vhgen.sensor.state import HOLE_CAUSES


@numba.njit(cache=True)
def _decode(out, flags, ids, view_ids, want_raw, depth_mm, raw, labels, instances, classes,
            view_instances, counts):
    # one loop an output, each simple enough to vectorise (one loop with them all and
    # its branches took 6 ns a pixel here, these together under 2)
    n = out.shape[0]
    valid = 0
    for p in range(n):
        mm = out[p] & 0xFFFF
        depth_mm[p] = mm
        valid += mm > 0
    if want_raw:
        for p in range(n):
            raw[p] = out[p] >> 16
    for p in range(n):
        i = ids[p]
        labels[p] = i & 0xFF
        instances[p] = (i >> 8) & 0xFF
        classes[p] = (i >> 16) & 0xFF
    for p in range(n):
        view_instances[p] = (np.uint32(view_ids[p]) >> 8) & 0xFF
    ncauses = counts.shape[0]
    hist = np.zeros(2 << ncauses, np.int64)  # holes by flags word (bit c + 1: cause c)
    for p in range(n):
        f = flags[p]
        if f > 1:  # not valid (bit 0) alone
            if f < hist.shape[0]:
                hist[f] += 1
            else:  # a bit beyond the causes: count this one's causes here
                for c in range(ncauses):
                    if f & (2 << c):
                        counts[c] += 1
    for f in range(2, hist.shape[0]):
        if hist[f]:
            for c in range(ncauses):
                if f & (2 << c):
                    counts[c] += hist[f]
    return valid


@dataclass(frozen=True, eq=False)
class FrameWords:
    """What a frame keeps of its sensor output, (H, W) each: ``depth_mm`` uint16,
    ``raw11`` uint16 or None, ``labels`` / ``instances`` / ``classes`` uint8 (the ids the
    sensor moved with the pixels), ``view_instances`` uint8 (the rendered view's, before
    the sensor), ``holes`` {cause: pixels} as ``SensorOutput.holes`` (``no_hit`` always,
    every other cause where it has a pixel), ``valid_pixels``."""

    depth_mm: np.ndarray
    raw11: np.ndarray | None
    labels: np.ndarray
    instances: np.ndarray
    classes: np.ndarray
    view_instances: np.ndarray
    holes: dict[str, int]
    valid_pixels: int


def decode(words: np.ndarray, view_ids: np.ndarray, height: int, width: int,
           raw11: bool) -> FrameWords:
    """``words``: the 4 x H x W uint32 output words (encoded depth and raw, flags,
    disparity, packed ids); ``view_ids``: the rendered view's packed ids as float32
    (H x W); ``raw11``: whether the sensor's encoding keeps the raw value."""
    n = height * width
    w = np.asarray(words, np.uint32).reshape(4, n)
    shape = (height, width)
    depth_mm = np.empty(shape, np.uint16)
    raw = np.empty(shape if raw11 else (1, 1), np.uint16)
    labels, instances, classes, view_instances = (np.empty(shape, np.uint8)
                                                  for _ in range(4))
    counts = np.zeros(len(HOLE_CAUSES), np.int64)
    valid = _decode(w[0], w[1], w[3], np.asarray(view_ids, np.float32).reshape(n), raw11,
                    depth_mm.reshape(n), raw.reshape(-1), labels.reshape(n),
                    instances.reshape(n), classes.reshape(n), view_instances.reshape(n),
                    counts)
    holes = {c: int(counts[i]) for i, c in enumerate(HOLE_CAUSES)
             if c == "no_hit" or counts[i] > 0}
    return FrameWords(depth_mm, raw if raw11 else None, labels, instances, classes,
                      view_instances, holes, int(valid))


def warm() -> None:
    """Load (or compile) the kernel for the types :func:`decode` passes."""
    decode(np.zeros(4 * 4, np.uint32), np.zeros(4, np.float32), 2, 2, True)

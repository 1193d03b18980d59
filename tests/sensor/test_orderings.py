"""Property: any ordering of the shipped effects, with any parameter values, either loads
and runs, or is refused when the sensor is loaded. Nothing fails on a frame."""

import dataclasses

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vhgen.camera import Intrinsics
from vhgen.errors import ConfigError
from vhgen.sensor.sensor_config import SensorConfig, parse_effects
from vhgen.sensor.simulator import SensorModel
from vhgen.sensor.spec import Choice, Encoding, Flag, Number, effect_types

H, W, F, B = 24, 40, 57.1, 0.075
INTR = Intrinsics(W, H, F, F, (W - 1) / 2, (H - 1) / 2)
# the shipped effects (an example effect imported by another test does not join in)
SHIPPED = sorted(n for n, c in effect_types().items() if c.__module__ == "vhgen.sensor.effects")
SPECS = {**{n: effect_types()[n] for n in SHIPPED}, Encoding.name: Encoding}


def _frame():
    v, u = np.mgrid[0:H, 0:W]
    z = np.where(u < W // 2, 3.0, 1.0) + 0.05 * np.sin(v / 3.0)
    z[:3, :5] = 0.0
    z[3, :4] = [np.nan, np.inf, -1.0, 70.0]
    n = np.ones((H, W), np.float32)  # facing the camera
    n[:, :6] = 0.0  # grazing
    proj = np.where(u < W // 2 - 4, 3.0, 1.0)
    labels = np.where(u < W // 2, 1, 2).astype(np.uint8)
    return z, n, proj, labels


def _value(kind):
    """Values in the field's range, and now and then one that is not."""
    if isinstance(kind, Number):
        lo = -1e3 if kind.lo is None else kind.lo
        hi = 1e3 if kind.hi is None else kind.hi
        good = (st.integers(int(np.ceil(lo)), int(hi)) if kind.integer
                else st.floats(lo, hi, allow_nan=False))
        if kind.odd:
            good = good.map(lambda v: v - 1 + v % 2 if v > lo else v + 1 - v % 2)
        bad = st.one_of(st.floats(allow_nan=True), st.integers(-10**6, 10**6),
                        st.text(max_size=3), st.booleans())
    elif isinstance(kind, Choice):
        good, bad = st.sampled_from(kind.options), st.text(max_size=5)
    else:
        good, bad = st.booleans(), st.integers(-2, 2)
    # hypothesis favours simple branches: weight the good one explicitly
    return st.integers(0, 9).flatmap(lambda k: bad if k == 9 else good)


@st.composite
def _effect(draw, name):
    params = {}
    for f in dataclasses.fields(SPECS[name]):
        kind = f.metadata.get("kind")
        if isinstance(kind, (Number, Choice, Flag)) and draw(st.booleans()):
            params[f.name] = draw(_value(kind))
    return {name: params}


@st.composite
def _effect_lists(draw):
    names = draw(st.permutations(SHIPPED))
    names = names[:draw(st.integers(1, len(names)))]
    if draw(st.booleans()):  # the encoding: usually last, where it belongs
        misplaced = draw(st.integers(0, 4)) == 4
        names.insert(draw(st.integers(0, len(names))) if misplaced else len(names),
                     Encoding.name)
    return [draw(_effect(n)) for n in names]


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_effect_lists(), st.integers(0, 2**32 - 1))
def test_any_ordering_loads_and_runs_or_is_refused_at_load(effects, seed):
    try:
        specs, encoding = parse_effects(effects, "fuzz.yaml")
    except ConfigError as e:
        assert e.source == "fuzz.yaml" and e.field.startswith("effects") and e.message
        return
    cfg = SensorConfig("fuzz", INTR, B, specs, encoding, pattern_seed=1)
    z, n, proj, labels = _frame()
    model = SensorModel(cfg)
    for k in range(2):  # the second frame exercises the stages' caches
        out = model.simulate(z, np.random.default_rng(seed + k), labels=labels, incidence=n,
                             projector_depth=proj)
    assert out.depth_mm.shape == (H, W) and out.depth_mm.dtype == np.uint16
    assert np.isfinite(out.disparity).all()
    assert (out.depth_mm[~out.valid] == 0).all()
    assert out.labels is not None and out.labels.shape == (H, W)
    if encoding.raw11:
        assert out.raw11 is not None and (out.raw11[~out.valid] == 2047).all()

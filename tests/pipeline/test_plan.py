import numpy as np

from vhgen.job_config import AvatarConfig
from vhgen.pipeline.plan import avatar_params, frame_seed, make_plan


def test_plan_covers_every_frame_once_and_is_deterministic():
    a = make_plan(5, num_poses=23, avatars=AvatarConfig(3, (0.9, 1.1)), frames_per_shard=8)
    b = make_plan(5, num_poses=23, avatars=AvatarConfig(3, (0.9, 1.1)), frames_per_shard=8)
    assert a.num_frames == 69
    covered = np.concatenate([np.arange(t.start, t.stop) for t in a.tasks])
    np.testing.assert_array_equal(covered, np.arange(69))
    assert [t.shard for t in a.tasks] == list(range(9))
    np.testing.assert_array_equal(a.seeds, b.seeds)
    assert a.avatars == b.avatars
    assert len(np.unique(a.seeds)) == 69


def test_seed_depends_only_on_its_inputs():
    s = frame_seed(1, 2, 3)
    assert s == frame_seed(1, 2, 3)
    assert len({s, frame_seed(2, 2, 3), frame_seed(1, 3, 3), frame_seed(1, 2, 4),
                frame_seed(1, 2, 3, camera=1)}) == 5
    # a frame's seed does not depend on the shard size (the worker partition)
    p1 = make_plan(9, 10, AvatarConfig(2, (1, 1)), 3)
    p2 = make_plan(9, 10, AvatarConfig(2, (1, 1)), 7)
    np.testing.assert_array_equal(p1.seeds, p2.seeds)


def test_avatar_params_in_range():
    cfg = AvatarConfig(50, (0.9, 1.1))
    scales = [avatar_params(3, a, cfg).scale for a in range(50)]
    assert min(scales) >= 0.9 and max(scales) <= 1.1 and len(set(scales)) == 50

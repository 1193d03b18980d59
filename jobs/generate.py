"""Ray job entrypoint: the same code as ``vhgen generate`` on an existing cluster.

    ray job submit --working-dir . -- python jobs/generate.py configs/scenes/default.yaml \
        --out /shared/datasets/default.zarr

Inside a Ray job RAY_ADDRESS is set, so the driver joins the cluster instead of starting
a local Ray.
"""

import sys

from vhgen.cli import main

if __name__ == "__main__":
    sys.exit(main(["generate", *sys.argv[1:]]))

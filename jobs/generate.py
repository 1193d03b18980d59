"""Ray job entrypoint: the same code as ``vhgen generate`` on an existing cluster.

    ray job submit --working-dir . -- python jobs/generate.py configs/scenes/default.yaml \
        --out /shared/datasets/default.zarr

Inside a Ray job RAY_ADDRESS is set and the driver joins the cluster; ``--executor ray``
is passed first so that the workers are Ray actors even if it is not (a later
``--executor`` on the command line wins).
"""

import sys

from vhgen.cli import main

if __name__ == "__main__":
    sys.exit(main(["generate", "--executor", "ray", *sys.argv[1:]]))

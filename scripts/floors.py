"""The floors check's Python side (run by ``scripts/check_floors.sh`` in each venv).

  floors.py jobs OUT [NAME...]
                            run a person-only, a room, a cluttered-room and a
                            real-background job (and the person-only one on Ray) into
                            OUT with the vhgen of this
                            interpreter, read each back with vhgen.dataset, open each
                            manifest with this pyarrow; NAMEs: only those of JOBS
  floors.py read STORE...   open each store's manifest.parquet with this pyarrow alone
                            (no vhgen: the reader a user's training code has)
  floors.py form1 SRC DST   copy store SRC to DST with its manifest in form 1 (before
                            issue 29), to check that vhgen reads it with this pyarrow
  floors.py vread STORE...  read stores with vhgen.dataset (any form)
  floors.py same DIR1 DIR2  every store of DIR2 holds the same arrays as the store of its
                            name in DIR1, bit for bit (the floors against the newest)
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# (name, config, extra flags): every kind of job, a few frames each
JOBS = [("person_only", "default", ["--max-frames", "6"]),
        ("room", "living_room", ["--max-frames", "6"]),
        # clutter placement's numba kernels and their NumPy references: the same arrays
        # with the floors' numpy and numba as with the newest
        ("cluttered", "cluttered_room", ["--max-frames", "6"]),
        ("real_background", str(REPO / "docs" / "examples" / "real_room.yaml"),
         ["--max-frames", "6"]),
        ("person_only_ray", "default", ["--max-frames", "6", "--executor", "ray"])]


def versions() -> str:
    import importlib.metadata as md

    names = ["numpy", "pyarrow", "zarr", "moderngl", "trimesh", "ray", "numba", "scipy",
             "pillow", "matplotlib"]
    out = []
    for n in names:
        try:
            out.append(f"{n} {md.version(n)}")
        except md.PackageNotFoundError:
            pass
    return ", ".join(out)


def vread(store: Path) -> str:
    import numpy as np

    import vhgen.dataset as vd

    ds = vd.open(store)
    n = 0
    for i in range(len(ds)):
        item = ds[i]
        assert item["frame"] == i and item["depth"].dtype == np.uint16
        assert item["manifest"]["frame"] == i
        n += int((item["labels"] > 0).sum())
    return f"{len(ds)} frames, {n} body pixels"


def read(store: Path) -> str:
    import pyarrow.parquet as pq

    t = pq.read_table(store / "manifest.parquet")
    people = t.column("people").to_pylist()
    feet = sum(p["footprint"] is not None for row in people for p in row)
    return f"{t.num_rows} rows, {feet} footprints"


def main(argv: list[str]) -> int:
    mode, args = argv[0], [Path(a) for a in argv[1:]]
    print(f"# {Path(sys.executable).parent.parent.name}: {versions()}", flush=True)
    if mode == "jobs":
        out, only = args[0], {str(a) for a in args[1:]}
        unknown = only - {name for name, _, _ in JOBS}
        if unknown:
            print(f"FAIL: no such job: {sorted(unknown)}")
            return 2
        vhgen = Path(sys.executable).with_name("vhgen")
        for name, config, flags in JOBS:
            if only and name not in only:
                continue
            t0 = time.perf_counter()
            store = out / f"{name}.zarr"
            r = subprocess.run([str(vhgen), "-q", "generate", config, "--out", str(store),
                                "--backend", "osmesa", "--num-workers", "2", "--overwrite",
                                *flags], capture_output=True, text=True)
            if r.returncode:
                print(f"FAIL job {name}: {r.stderr.strip()[-2000:]}")
                return 1
            print(f"job {name}: {vread(store)}; pyarrow reads {read(store)} "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
    elif mode == "read":
        for store in args:
            print(f"read {store.parent.name}/{store.name}: {read(store)}")
    elif mode == "vread":
        for store in args:
            print(f"vhgen reads {store.parent.name}/{store.name}: {vread(store)}")
    elif mode == "same":
        import numpy as np
        import zarr

        a_dir, b_dir = args
        stores = sorted(b_dir.glob("*.zarr"))  # every store of DIR2, each also in DIR1
        if not stores or any(not (a_dir / b.name).is_dir() for b in stores):
            print(f"FAIL: {b_dir} has no stores or one that {a_dir} lacks")
            return 1
        for b in stores:
            a = a_dir / b.name
            ga, gb = (zarr.open_group(str(p), mode="r") for p in (a, b))
            for name in ("depth", "labels", "raw", "instances", "classes"):
                if name in ga and not np.array_equal(ga[name][:], gb[name][:]):
                    print(f"FAIL {a.name}: {name} differs between {a_dir} and {b_dir}")
                    return 1
            print(f"same arrays: {a.name}")
    elif mode == "form1":
        import pyarrow.parquet as pq

        sys.path.insert(0, str(REPO))
        from tests.store.test_portable import _as_form1

        src, dst = args
        shutil.rmtree(dst, ignore_errors=True)
        shutil.copytree(src, dst)
        pq.write_table(_as_form1(pq.read_table(src / "manifest.parquet")),
                       dst / "manifest.parquet", compression="zstd")
        print(f"form 1 copy of {src.name} in {dst}")
    else:
        print(__doc__)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

import subprocess
import sys


def test_import_vhgen_loads_neither_gl_nor_ray():
    code = ("import sys, vhgen; vhgen.read_bvh; "
            "bad = [m for m in ('moderngl', 'glcontext', 'ray') if m in sys.modules]; "
            "print(','.join(bad)); sys.exit(1 if bad else 0)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_public_api_listed():
    import vhgen

    for name in vhgen.__all__:
        assert hasattr(vhgen, name), name

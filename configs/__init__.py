"""vhgen's shipped configs (scenes, sensors, label schemes, retarget maps), packaged as
``vhgen.configs`` (setup.py maps this folder into the wheel; read with importlib.resources)."""

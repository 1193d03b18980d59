"""How good the output is, behind the ``vhgen bench`` commands: the sensor against its
structured-light reference on the fidelity scene suite (``vhgen bench fidelity``) and vhgen
frames against real ones (``vhgen bench realism``). Needs the whole stack (GL, the
pipeline); nothing below this layer imports it. Speed and memory are measured by the
scripts in ``benchmarks/``, not here."""

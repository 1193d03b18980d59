"""Realism of depth frames, measured: statistics of one frame (:mod:`.stats`), the same
statistics on real and vhgen frames side by side with one distance each
(:mod:`.compare`), plots (:mod:`.plots`), and a sensor fitted to real frames
(:mod:`.fit`, ``vhgen sensor fit``). Pure math on arrays; scipy and matplotlib are
imported inside functions."""

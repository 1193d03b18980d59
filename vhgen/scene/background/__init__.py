"""Real depth frames as backgrounds (pure): their floor, their free floor, and people
placed on it.

A background is a real depth frame (read by :mod:`vhgen.depthfile`) of a room, taken by
the camera the job's sensor model describes.

* :mod:`~vhgen.scene.background.floor`: a frame's floor plane (RANSAC) and free floor;
* :mod:`~vhgen.scene.background.load`: the job's backgrounds, read and checked once
  (:func:`~vhgen.scene.background.load.load_backgrounds`, called by ``prepare_job``);
* :mod:`~vhgen.scene.background.people`: per frame, a background drawn and the people
  placed on its free floor (:func:`~vhgen.scene.background.people.layout_background`);
* :mod:`~vhgen.scene.background.background_frame`: the floor plane and a frame's
  background as data (in the frame description and the manifest).

Import from the modules: this package's ``__init__`` imports nothing, as the frame
description imports the data module and the placement imports the description.
"""

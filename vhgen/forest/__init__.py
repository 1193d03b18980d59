"""Shotton-style body-part forests trained on vhgen frames (pure NumPy/numba; no GL, no Ray).

features : the depth-comparison feature, evaluated as PCL's people detector does
train    : level-wise training from class histograms over image shards
model    : the forest arrays, file format and compiled inference
pcl      : PCL gpu/people text tree format (export/import)
evaluate : accuracy, confusion matrix, contact sheets
distributed : the same training on Ray actors (imports Ray lazily)
"""

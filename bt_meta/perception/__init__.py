"""Perception for bt-meta: what the robot sees, turned into the representations its expectations compare.

Offers:

* :mod:`bt_meta.perception.hsv` -- HSV blob detection on a top view: blocks with colour, shape (1x1/1x2 against
  lb), centroid and orientation in table coordinates; thresholds as data; pixel <-> table-plane projection
* :mod:`bt_meta.perception.gridmap` -- the paper's 3 lb x 3 lb, 6 x 6 grid-maps and their image crops
* :mod:`bt_meta.perception.topview` -- one top view analysed: blocks, their grid-maps, crops anywhere on demand
* :mod:`bt_meta.perception.keypoints` -- the keypoint relations R_p, R_n and their means over past traces
* :mod:`bt_meta.perception.synthetic` -- synthetic top views with exact answers, for tests
* :mod:`bt_meta.perception.recall` -- how expectation plugins find the memory and the remembered states of a step
"""

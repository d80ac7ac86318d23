"""Sensing as fallible as a real robot's: noise models and the perceived symbolic state monitors compare with.

* :mod:`bt_meta.sensing.noise` -- pixel noise, lighting, depth noise, camera pose error, occlusion by the arm
* :mod:`bt_meta.sensing.perceived` -- the perception plugin deriving the symbolic state from sensing
"""

"""Camera perception: blocks and grid-maps from a top view of the table (paper, section 6.3).

After every successful primitive, when the world has a top camera, one frame is rendered and analysed: HSV blobs
become blocks (colour, shape 1x1/1x2, centroid, orientation in table coordinates) and each block gets its 3 lb x
3 lb grid-map. The world's camera is ``world.top_camera`` when it has one; a world built on the pybullet
simulator (``world.sim``) gets a :class:`~bt_meta.world.simulation.camera.TopViewCamera` of its own, made once. Blocks
are
named after the simulator's objects they lie on (the nearest object within half a block), so remembered and
observed grid-maps of the same block can be paired; the geometry itself comes from the image only.

Settings (:func:`configure`): HSV thresholds (a mapping, see :meth:`HSVThresholds.from_mapping`; default: derived
from every colour the scene format defines, see :mod:`bt_meta.perception.colours`), the grid spec,
whether to use the depth image, the camera's centre and height.

Offers:

* :class:`CameraPerception` -- the plugin as an object (register your own instance for other settings)
* :func:`bt_meta_observe` -- ``{"blocks": [...], "gridmaps": [GridMap, ...], "image": TopView,
  "object_gridmaps": {name: GridMap}}``: detected blocks (with ``name`` when matched), one grid-map per detected
  block, the analysed view (crops anywhere on demand), and -- in the simulator -- one grid-map per block object
  centred where it truly is (the instructor's annotation when recording a demonstration); only the keys the
  observe request wants (:class:`~bt_meta.bt.expectations.ObserveRequest`, ``image`` with any of them), and no
  frame at all when it wants none of them
* :func:`configure` -- replace the settings of the module-level plugin
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping
from typing import Any

from bt_meta.bt.expectations import OBSERVE_ALL
from bt_meta.perception.colours import scene_thresholds
from bt_meta.perception.gridmap import DEFAULT_SPEC, GridSpec
from bt_meta.perception.hsv import HSVThresholds
from bt_meta.perception.topview import TopView, capture
from bt_meta.plugins import ConfiguredPlugin, hookimpl
from bt_meta.world.simulation.objects import LB

VIEW_KEYS = ("image", "blocks", "gridmaps", "object_gridmaps")
"""The observation keys made from the top view: no request wants any of them, no frame is rendered."""

TABLE_COLOUR = (0.93, 0.9, 0.83, 1.0)
"""The simulator's table (RGBA), the background thresholds are derived on when the world does not say."""


class CameraPerception:
    """Top-view perception with fixed settings; one camera per simulator, made on first use.

    ``thresholds`` ``None`` (default): derived from every colour the scene format defines, on the simulator's
    table colour (:func:`bt_meta.perception.colours.scene_thresholds`), so a block of any declared colour is seen.
    """

    def __init__(
        self,
        *,
        thresholds: HSVThresholds | Mapping[str, Any] | None = None,
        spec: GridSpec = DEFAULT_SPEC,
        use_depth: bool = True,
        camera_centre: tuple[float, float] | None = None,
        camera_height: float = 1.0,
        name_radius: float = 0.5 * LB,
    ) -> None:
        if isinstance(thresholds, Mapping):
            thresholds = HSVThresholds.from_mapping(thresholds)
        self.thresholds = thresholds
        self.spec = spec
        self.use_depth = use_depth
        self.camera_centre = camera_centre
        self.camera_height = camera_height
        self.name_radius = name_radius
        self._cameras: weakref.WeakKeyDictionary[Any, Any] = weakref.WeakKeyDictionary()

    def camera_for(self, world: Any) -> Any:
        """The world's top camera, or one made for its simulator, or ``None``."""
        camera = getattr(world, "top_camera", None)
        if camera is not None:
            return camera
        sim = getattr(world, "sim", None)
        if sim is None or not hasattr(sim, "table"):
            return None
        camera = self._cameras.get(sim)
        if camera is None:
            from bt_meta.world.simulation.camera import TopViewCamera

            options: dict[str, Any] = {"height": self.camera_height}
            if self.camera_centre is not None:
                options["centre"] = self.camera_centre
            camera = self._cameras[sim] = TopViewCamera(sim, **options)
        return camera

    def look(self, world: Any) -> TopView | None:
        """One analysed top view of ``world`` (``None`` without a camera)."""
        camera = self.camera_for(world)
        if camera is None:
            return None
        sim = getattr(camera, "sim", None)
        namer = None
        if sim is not None and hasattr(sim, "object_states"):
            # Pair blocks with the simulator's objects by position only (for names; geometry is the image's).
            centres = {name: s.pose[:2] for name, s in sim.object_states().items() if s.shape is not None}
            radius = self.name_radius

            def namer(block: Any) -> str | None:
                best, best_d = None, radius
                for name, (x, y) in centres.items():
                    d = math.hypot(x - block.centroid[0], y - block.centroid[1])
                    if d <= best_d:
                        best, best_d = name, d
                return best

        return capture(camera, thresholds=self.thresholds_for(world), spec=self.spec, use_depth=self.use_depth,
                       namer=namer)

    def thresholds_for(self, world: Any) -> HSVThresholds:
        """The configured thresholds, or those derived from the declared colours on the world's table colour."""
        if self.thresholds is not None:
            return self.thresholds
        table = getattr(getattr(world, "sim", None), "table", None)
        return scene_thresholds(getattr(table, "colour", None) or TABLE_COLOUR)

    def object_grid_maps(self, world: Any, view: TopView) -> dict[str, Any]:
        """One grid-map per simulator block, centred where the block truly is: the instructor's annotation of
        section 6.3 ("the block which was placed as well as its location"), for recording demonstrations."""
        sim = getattr(world, "sim", None)
        if sim is None or not hasattr(sim, "object_states"):
            return {}
        maps = {}
        for name, state in sim.object_states().items():
            if state.shape is None:
                continue
            block = view.block_near(state.pose[:2], self.name_radius)
            maps[name] = view.grid_map_at(state.pose[:2], z=None if block is None else block.top_z,
                                          object_name=name, colour=state.colour, shape=state.shape)
        return maps

    @hookimpl
    def bt_meta_observe(self, world: Any, context: Any, request: Any) -> dict[str, Any] | None:
        """Render and analyse a top view only when ``request`` wants one of the keys made from it; of those,
        only the wanted ones are computed (the blocks' descriptions and the true-pose grid-maps cost per block)."""
        if request is None:
            request = OBSERVE_ALL
        if not request.wants(*VIEW_KEYS):
            return None
        view = self.look(world)
        if view is None:
            return None
        out: dict[str, Any] = {"image": view}
        if request.wants("blocks"):
            out["blocks"] = view.describe()
        if request.wants("gridmaps"):
            out["gridmaps"] = list(view.grid_maps)
        if request.wants("object_gridmaps"):
            out["object_gridmaps"] = self.object_grid_maps(world, view)
        return out


plugin = ConfiguredPlugin(CameraPerception)
configure = plugin.configure


@hookimpl
def bt_meta_observe(world: Any, context: Any, request: Any) -> dict[str, Any] | None:
    return plugin.current.bt_meta_observe(world, context, request)

"""The scene handle: a scene prepared on one device at one precision, owned by the caller, and every
query on it as a method (Open3D's RaycastingScene, Embree's RTCScene, Mitsuba's loaded Scene).

    with pyclray.prepare(scene) as tracer:
        frame = tracer.render(aovs=("depth", "id"))
        hits = tracer.cast(origins, directions)

All the device state of a scene lives here: the prepared shapes (engine/scene/prepared.py), what each view
needs besides them (engine/scene/views.py: the camera, lights, tile lists, acceleration choice and range
check), cast's inputs and, on devices other than CPUs, the images' buffers. Its memory is
``nbytes``; ``close()`` (or leaving the ``with`` block) frees it, after which the handle refuses
every query with a clear error. The module-level functions (pyclray.render, pyclray.cast, ...) are
thin wrappers over a small cache of these (engine/api.py).
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import replace

from ..model.aovs import AOVS, CAST_AOVS
from ..model.errors import RequestError
from ..model.frames import derivation
from ..model.loader import as_scene
from ..model.scene import Scene, check_shape_count
from .launch.run import OutputBuffers
from .opencl.buffers import KeptBuffers
from .opencl.device import context_for, gpu_class
from .queries import cast as cast_queries
from .queries import cast_device as device_casts
from .queries import closest as closest_queries
from .queries import hits as hit_queries
from .queries import render as render_query
from .queries import scan as scan_query
from .queries.requests import check_precision, check_request
from .scene.prepared import PreparedScene
from .scene.views import ViewState


class Tracer:
    """A scene's shapes prepared on one device at one precision, and the queries on them (see the
    module's docstring). ``pyclray.prepare(scene, device, precision)`` makes one."""

    VIEWS_MAX = 16  # the views (camera, image, lights, shading) whose inputs are kept

    def __init__(self, scene: Scene, device=None, precision: str = "fp32"):
        if not isinstance(scene, Scene):  # (pyclray.prepare also takes a scene file's path)
            raise RequestError(f"scene: expected a pyclray.Scene, got {type(scene).__name__}")
        check_shape_count(scene)  # before anything is prepared
        ctx = context_for(device)
        check_precision(precision, ctx)
        self.ctx, self.precision = ctx, precision
        self.lock = threading.RLock()  # the handle's own state: its views, cast inputs, updates
        self._scene = scene
        self._prepared: PreparedScene | None = PreparedScene(ctx, scene.shapes, precision)
        self._views: OrderedDict = OrderedDict()  # (camera, image, lights, shading) -> ViewState
        self._cast_inputs = None  # cast's buffers, made at the first cast (engine/queries/cast.py: cast_inputs)
        # the closest-point query's inputs, and the handles of the closed and of the open meshes alone
        # (sign="parity" and "winding"), made when first asked for (engine/queries/closest.py)
        self._closest_inputs = None
        self._mesh_handles: dict = {}
        self._scan_still = None  # (shapes, Tracer): a sweeping scan's still shapes, prepared once (see scan)
        self.outputs = OutputBuffers()
        self.ray_buffers = KeptBuffers()  # small casts' rays and results (engine/queries/cast.py: run_cast)

    # -- its life --------------------------------------------------------------------------------
    def close(self) -> None:
        """Free the device memory it holds (kernels still running keep what they read until done).
        Any later query is an error; closing again does nothing."""
        with self.lock:
            self._prepared = None
            self._views.clear()
            self._cast_inputs = None
            self._drop_closest()
            if self._scan_still is not None:
                self._scan_still[1].close()
                self._scan_still = None
            self.outputs.buffers.clear()
            self.ray_buffers.clear()

    @property
    def closed(self) -> bool:
        return self._prepared is None

    def __enter__(self) -> "Tracer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self.closed else f"{len(self._prepared.shapes)} shapes, {self.nbytes} bytes"
        return f"<pyclray.Tracer {self.precision} on {self.ctx.device.name.strip()}: {state}>"

    @property
    def prepared(self) -> PreparedScene:
        """The prepared shapes (engine/scene/prepared.py); a RequestError once the handle is closed."""
        prepared = self._prepared
        if prepared is None:
            raise RequestError("this pyclray.Tracer is closed: prepare the scene again (pyclray.prepare)")
        return prepared

    @property
    def scene(self) -> Scene:
        """The scene it was prepared for, or last updated to: its camera, image, lights and shading
        are render's defaults."""
        return self._scene

    @property
    def shapes(self) -> tuple:
        return self.prepared.shapes

    @property
    def nbytes(self) -> int:
        """The bytes of device memory it holds: the shapes, the BVH, each kept view's inputs, cast's
        buffers and the images' buffers (on a CPU device these are host memory the device uses)."""
        with self.lock:
            if self._prepared is None:
                return 0
            total = self._prepared.nbytes() + self.outputs.nbytes() + self.ray_buffers.nbytes()
            total += 0 if self._scan_still is None else self._scan_still[1].nbytes
            total += sum(state.nbytes() for state in self._views.values())
            total += 0 if self._closest_inputs is None else self._closest_inputs.nbytes
            total += sum(handle.nbytes for handle in self._mesh_handles.values() if handle is not None)
            return total + (0 if self._cast_inputs is None else self._cast_inputs[3])

    # -- renders ---------------------------------------------------------------------------------
    def render(self, camera=None, aovs=AOVS, window=None, acceleration: str = "auto"):
        """Render the handle's scene (its image size, lights and shading) from its camera, or from
        ``camera`` (a pyclray.Camera) instead: exactly ``pyclray.render(scene, aovs, precision,
        device, window, acceleration, camera)`` (see there), without preparing anything again."""
        return self.start_render(self._view(camera), aovs, window, acceleration)()

    def render_views(self, cameras, aovs=AOVS, acceleration: str = "auto", motion=None):
        """Yield the Frame of each camera (a pyclray.Camera, or a Scene whose camera and image size
        are taken), in order: exactly ``pyclray.render_views(scene, cameras, ...)``. The next view is
        enqueued before a frame is returned (the host's work for it overlaps the device's run of this
        one); an error of a view is raised after the frames before it. motion: the next frame's
        shapes for flow (engine/queries/motion.py: Motion, its camera None: each view's own)."""
        return self.views_of(self._scene, cameras, aovs, acceleration, motion)

    def _view(self, camera) -> Scene:
        if camera is None:
            return self._scene
        return render_query.with_camera(self._scene, camera)

    def start_render(self, view: Scene, aovs, window=None, acceleration: str = "auto", motion=None, warn_pose=True):
        """Enqueue a render of ``view`` (a Scene with this handle's shapes) and return a callable that
        waits for it and returns its Frame (engine/queries/render.py: start; motion: for flow;
        warn_pose: the all-miss pose warning, off for a part of a scene)."""
        return render_query.start(self, view, aovs, window, acceleration, motion, warn_pose)

    def views_of(self, scene: Scene, cameras, aovs=AOVS, acceleration: str = "auto", motion=None):
        """render_views of ``scene`` (this handle's shapes, its own lights and shading) from each camera."""
        pending = None
        try:
            for camera in cameras:
                try:
                    if isinstance(camera, Scene):
                        view = replace(scene, camera=camera.camera, image=camera.image)
                    else:
                        view = render_query.with_camera(scene, camera)
                    started = self.start_render(view, aovs, acceleration=acceleration, motion=motion)
                except Exception:
                    if pending is not None:  # the frames before it first
                        frame, pending = pending(), None
                        yield frame
                    raise
                if pending is not None:
                    frame, pending = pending(), None
                    yield frame
                pending = started
            if pending is not None:
                frame, pending = pending(), None
                yield frame
        finally:
            if pending is not None:  # left early: the last view's kernel still writes into its arrays
                pending()

    def view_state(self, view: Scene) -> ViewState:
        """What this handle keeps of a view (engine/scene/views.py: ViewState), by the view's camera, image,
        lights and shading (equal values share it), the VIEWS_MAX most recent."""
        key = (view.camera, view.image, view.lights, view.shading)
        with self.lock:
            self.prepared  # closed: the error, before anything is made
            state = self._views.get(key)
            if state is None:
                state = self._views[key] = ViewState()
                while len(self._views) > self.VIEWS_MAX:
                    self._views.popitem(last=False)
            else:
                self._views.move_to_end(key)
            return state

    # -- casts -----------------------------------------------------------------------------------
    def cast(self, origins, directions, aovs=AOVS, tmin=0.0, tmax=None, out="host"):
        """The nearest hit t in (tmin, tmax) of each ray: exactly ``pyclray.cast(scene, origins,
        directions, aovs, precision, device, tmax, tmin)`` (see there). origins and directions may
        also be pyopencl arrays (float32 or float64) on this handle's context, used where they are;
        out="device" returns the Frame's arrays as pyopencl arrays on it (docs/python.md)."""
        aovs = check_request(aovs, self.precision, self.ctx, CAST_AOVS)
        cast_queries.check_cast_device(self.ctx)
        return self._run_cast("cast", origins, directions, tmax, aovs, tmin, out)

    def occluded(self, origins, directions, tmin=0.0, tmax=None, out="host"):
        """Whether each ray hits any shape at t in (tmin, tmax): exactly ``pyclray.occluded(scene,
        origins, directions, tmax, precision, device, tmin)`` (see there); device arrays and out as
        for cast."""
        cast_queries.check_cast_device(self.ctx)
        return self._run_cast("occluded", origins, directions, tmax, (), tmin, out)

    def _run_cast(self, query, origins, directions, tmax, aovs, tmin, out):
        """Rays given as pyopencl arrays, results asked for on the device (out="device"), or any rays
        on a device of the GPU class (engine/opencl/device.py: gpu_class) go through
        engine/queries/cast_device.py; host arrays to host results on a CPU through cast.py."""
        if device_casts.check_out(out) == "device" or device_casts.is_device_array(origins) \
                or device_casts.is_device_array(directions) or gpu_class(self.ctx.device):
            return device_casts.run_cast_device(self, query, origins, directions, tmax, aovs, tmin, out)
        return cast_queries.run_cast(self, query, origins, directions, tmax, aovs, tmin)

    # -- hit counts ------------------------------------------------------------------------------
    def count_hits(self, origins, directions, tmin=0.0, tmax=None):
        """How many times each ray crosses the shapes' surfaces at t in (tmin, tmax), without storing
        the hits: exactly ``pyclray.count_hits(scene, origins, directions, tmin, tmax, ...)`` (see there)."""
        cast_queries.check_cast_device(self.ctx)
        return hit_queries.run_count_hits(self, origins, directions, tmin, tmax)

    def all_hits(self, origins, directions, tmin=0.0, tmax=None, aovs=hit_queries.DEFAULT_HIT_AOVS):
        """Every hit t in (tmin, tmax) of each ray, nearest first, in CSR form: exactly
        ``pyclray.all_hits(scene, origins, directions, tmin, tmax, aovs, ...)`` (see there)."""
        aovs = hit_queries.check_hit_aovs(aovs)
        cast_queries.check_cast_device(self.ctx)
        return hit_queries.run_all_hits(self, origins, directions, tmin, tmax, aovs)

    def scan(self, lidar=None, time=None):
        """A LiDAR scan of the handle's scene: exactly ``pyclray.scan(scene, lidar, time, precision,
        device)`` (see there). On an animated scene the handle is updated to each time the scan
        needs, and back to the scene's own shapes after it; a sweep among moving shapes keeps a handle
        of the still shapes (in ``nbytes``, freed by ``close``) and updates one of the moving shapes."""
        cast_queries.check_cast_device(self.ctx)
        self.prepared  # closed: the error, before anything is cast
        animated = self._scene if self._scene.animation is not None else None

        def still(view):  # a sweep's still shapes: a handle of this one's, kept until they change
            with self.lock:
                if self._scan_still is None or self._scan_still[0] is not view.shapes:
                    if self._scan_still is not None:
                        self._scan_still[1].close()
                    self._scan_still = (view.shapes, Tracer(view, self.ctx.device, self.precision))
                return self._scan_still[1]

        handles = (still, lambda view: Tracer(view, self.ctx.device, self.precision))
        try:
            return scan_query.run_scan(self, self._scene, lidar, time, handles)
        finally:
            if animated is not None and not self.closed:
                self.update(animated)

    def cast_inputs(self):
        """cast's buffers of the shapes (engine/queries/cast.py: cast_inputs), made at the first cast."""
        with self.lock:
            prepared = self.prepared
            if self._cast_inputs is None:
                self._cast_inputs = cast_queries.cast_inputs(prepared)
                self.ray_buffers.launches.clear()  # (which held the last inputs' buffers: device.py's launch_kept)
            return self._cast_inputs

    # -- closest points, distances, inside ------------------------------------------------------
    def closest_points(self, points) -> dict:
        """The nearest surface point of each point: exactly ``pyclray.closest_points(scene, points,
        precision, device)`` (see there)."""
        cast_queries.check_cast_device(self.ctx)
        return closest_queries.closest_points(self, points)

    def distance(self, points):
        """The distance of each point to the nearest surface: exactly ``pyclray.distance(scene,
        points, ...)`` (see there)."""
        cast_queries.check_cast_device(self.ctx)
        return closest_queries.distance(self, points)

    def signed_distance(self, points, sign: str = "parity"):
        """The distance, negative inside a solid: exactly ``pyclray.signed_distance(scene, points,
        sign, ...)`` (see there)."""
        cast_queries.check_cast_device(self.ctx)
        return closest_queries.signed_distance(self, points, sign)

    def occupancy(self, points, sign: str = "parity"):
        """1 inside a solid (or on a surface), else 0, uint8: exactly ``pyclray.occupancy(scene,
        points, sign, ...)`` (see there)."""
        cast_queries.check_cast_device(self.ctx)
        return closest_queries.occupancy(self, points, sign)

    def closest_inputs(self):
        """The closest-point query's buffers of the shapes (engine/queries/closest.py: ClosestInputs),
        made at its first call."""
        with self.lock:
            prepared = self.prepared
            if self._closest_inputs is None:
                self._closest_inputs = closest_queries.ClosestInputs(prepared, prepared.shapes)
            return self._closest_inputs

    def mesh_handle(self, closed: bool, precision: str | None = None):
        """A handle of this scene's closed meshes alone (closed=True: sign="parity" counts their
        crossings, "winding" signs them), or of its open ones (their hierarchical winding number),
        in this handle's precision or the one given (occupancy's fp32 count narrows its undecided
        points in fp64: engine/queries/closest.py); None where it has none; made when first asked for."""
        key = (closed, precision or self.precision)
        with self.lock:
            self.prepared
            if key not in self._mesh_handles:
                scene = closest_queries.meshes_scene(replace(self._scene, shapes=self.prepared.shapes), closed)
                self._mesh_handles[key] = None if scene is None else Tracer(scene, self.ctx.device, key[1])
            return self._mesh_handles[key]

    def _drop_closest(self) -> None:
        self._closest_inputs = None
        for handle in self._mesh_handles.values():
            if handle is not None:
                handle.close()
        self._mesh_handles = {}

    # -- a moved scene ---------------------------------------------------------------------------
    def update(self, scene) -> "Tracer":
        """Become the handle of ``scene``: its camera, image, lights and shading are the new
        defaults; where its shapes are this handle's but for some moved or changed ones (an
        animation's frame, ``scene.at(t)``; a tuple of as many shapes with some replaced), only those
        are rewritten and the BVH refitted above them; other shapes (added, removed, another type or
        primitive count, mesh instances) prepare the scene anew. The results are those of a handle
        prepared for ``scene``, bit for bit. Returns the handle."""
        scene = as_scene(scene)
        check_shape_count(scene)
        with self.lock:
            prepared = self.prepared
            shapes = scene.shapes
            if shapes is not prepared.shapes:
                derived = derivation(shapes)
                if derived is not None and derived[0] is prepared.base:
                    changed = derived[1]
                elif len(shapes) == len(prepared.shapes):
                    # changed from the shapes it holds now: those become the base the changes are from
                    changed = [i for i, (a, b) in enumerate(zip(shapes, prepared.shapes)) if a is not b]
                    prepared.base, prepared.dirty = prepared.shapes, set()
                else:
                    changed = None
                self.refit(shapes, changed)
            self._scene = scene
        return self

    def refit(self, shapes: tuple, changed) -> bool:
        """Update the prepared shapes in place for ``shapes`` (changed: the indices that differ from
        its base's, None: unknown), or prepare them anew where that cannot be done. True if in place."""
        with self.lock:
            prepared = self.prepared
            updated = False
            if changed is not None:
                with prepared.lock:
                    # an update writes the host arrays a CPU device reads: no kernel of a view still in
                    # flight (render_views enqueues the next view before returning a frame) may read them
                    prepared.ctx.queue.finish()
                    updated = prepared.update(shapes, changed)
            if updated:
                for state in self._views.values():
                    state.shapes_changed()
            else:
                self._prepared = PreparedScene(self.ctx, shapes, self.precision)
                if changed is not None:  # the base its changes are from, for the next frame's update
                    self._prepared.base, self._prepared.dirty = prepared.base, set(changed)
                self._views.clear()
            self._cast_inputs = None
            self._drop_closest()
            return updated


def prepare(scene, device=None, precision: str = "fp32") -> Tracer:
    """The scene prepared on a device (a pyopencl Device, a selector string, or None: the default)
    at a precision ("fp32" or "fp64"), once: a handle (Tracer) whose methods render, render views,
    cast and test occlusion without preparing anything again, until ``close()`` or the end of a
    ``with`` block frees its device memory. scene: a Scene or the path of a scene file."""
    return Tracer(as_scene(scene), device, precision)

"""The simulated depth camera: Drake's RgbdSensor (RenderEngineVtk) plus a LeafSystem that
samples it at the camera rate, corrupts the image like a structured-light sensor and
delivers it late.

The camera runs on its own clock (``camera.clock: free-running``): image ``k`` is
captured at ``t_k = phase + k / rate_hz + jitter_k``, with a random phase in one frame
period and Gaussian jitter (``jitter_std_s``), so frames fall between encoder readings,
as a real camera's do. ``encoder-grid`` moves every capture to the nearest encoder tick
instead. Python systems cannot schedule their own next update, so the schedule is drawn
once for a cycle of about ``SCHEDULE_CYCLE_S`` and repeats (one periodic event per frame
slot of the cycle, and one per arrival).

With ``camera.render_stride`` s > 1 the camera renders only what the subsampled image
needs: its pixels (s*i, s*j) of the full-resolution camera and their four
full-resolution neighbours (the silhouettes below need them), as two renders, the
kept rows at full width and the kept columns at full height (``grid_intrinsics``; a
quarter of the full image's pixels at s = 8). The delivered image is exactly
``core.camera.subsample`` of the full-resolution image, with the same silhouettes and
noise of the same law, drawn for the kept pixels only.

Per captured image ``k``:

* pixels where nothing was hit (too far) or closer than the near plane become NaN;
* silhouettes: a pixel whose 4-neighbour depth (at full resolution) differs by more
  than ``silhouette_threshold_m`` (or whose neighbour is invalid) becomes NaN, on both
  sides of the edge;
* depth-dependent Gaussian noise ``sigma(z) = noise_sigma0_m + noise_k_per_m * z^2`` (m);
* each pixel drops out (NaN) with probability ``dropout_probability``.

All randomness of image ``k`` comes from a counter-based generator keyed by
``(seed, CAMERA_STREAM, k)``, so the images do not depend on how often a Context was
copied or reset. The image is delivered as a :class:`DepthFrame` at
``t_k + delay_s`` carrying ``capture_time_s = t_k`` and ``sequence = k``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    ClippingRange,
    DepthRange,
    DepthRenderCamera,
    FrameId,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.sensors import ImageDepth32F, RgbdSensor

from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.sim.curved_shapes import tessellate_curved_perception
from drake_tracker.sim.scenario.config import CameraConfig
from drake_tracker.sim.streams import counter_generator

#: Name of the renderer the simulated camera uses.
RENDERER_NAME = "sim_vtk"
#: Random stream of the camera (the encoders use stream 0).
CAMERA_STREAM = 7
#: Random stream of the camera's clock (phase and jitter).
CLOCK_STREAM = 8
#: The capture schedule (phase and per-frame jitter) repeats after about this long (s).
SCHEDULE_CYCLE_S = 10.0
#: Event times that differ by less than this are the same instant (s).
TIME_TOLERANCE_S = 1e-7


def capture_schedule(config: CameraConfig, seed: int, encoder_period_s: float
                     ) -> tuple[np.ndarray, float]:
    """(capture offsets within one cycle, increasing, in [0, cycle); the cycle length)."""
    period = 1.0 / config.rate_hz
    slots = max(1, int(round(SCHEDULE_CYCLE_S / period)))
    nominal = np.arange(slots) * period
    if config.clock == "encoder-grid":
        h = float(encoder_period_s)
        cycle = max(1, round(slots * period / h)) * h
        return np.unique(np.round(nominal / h) * h % cycle), cycle
    cycle = slots * period
    rng = counter_generator(seed, 0, CLOCK_STREAM)
    phase = rng.uniform(0.0, period)
    jitter = np.clip(rng.normal(0.0, config.jitter_std_s, slots), -0.4 * period, 0.4 * period)
    return np.sort((phase + nominal + jitter) % cycle), cycle


def camera_intrinsics(config: CameraConfig) -> CameraIntrinsics:
    """Full-resolution intrinsics of the simulated camera (square pixels, centred)."""
    return CameraIntrinsics.from_fov(config.width, config.height, np.radians(config.fov_y_deg))


def grid_intrinsics(camera: CameraIntrinsics, stride_u: int, stride_v: int
                    ) -> CameraIntrinsics:
    """Intrinsics of the image of every ``stride_u``-th column and ``stride_v``-th row of
    ``camera``'s image, from pixel (0, 0): its pixel (i, j) looks along the ray of
    ``camera``'s pixel (stride_u*i, stride_v*j) (``CameraIntrinsics.subsampled`` when
    both strides are equal)."""
    if stride_u == stride_v:
        return camera.subsampled(stride_u)
    u, v = camera.subsampled(stride_u), camera.subsampled(stride_v)
    return dataclasses.replace(u, height=v.height, fy=v.fy, cy=v.cy)


def rendered_intrinsics(config: CameraConfig) -> CameraIntrinsics:
    """Intrinsics of the delivered images: the full-resolution camera subsampled by
    ``config.render_stride``."""
    return camera_intrinsics(config).subsampled(config.render_stride)


def ensure_vtk_renderer(scene_graph: SceneGraph, name: str = RENDERER_NAME) -> str:
    """Adds a headless RenderEngineVtk called ``name`` to ``scene_graph`` unless present."""
    if not scene_graph.HasRenderer(name):
        scene_graph.AddRenderer(name, MakeRenderEngineVtk(RenderEngineVtkParams()))
    return name


def depth_render_camera(config: CameraConfig, renderer_name: str = RENDERER_NAME,
                        strides: tuple[int, int] = (1, 1)) -> DepthRenderCamera:
    """Drake's depth camera for ``config``, full resolution or, with ``strides = (su,
    sv)``, its every su-th column and sv-th row (``grid_intrinsics``): clipping and depth
    range [near_m, far_m]."""
    intrinsics = grid_intrinsics(camera_intrinsics(config), *strides)
    core = RenderCameraCore(renderer_name, intrinsics.to_camera_info(),
                            ClippingRange(config.near_m, config.far_m), RigidTransform())
    return DepthRenderCamera(core, DepthRange(config.near_m, config.far_m))


def invalidate_no_hits(depth_m: np.ndarray, near_m: float, far_m: float) -> np.ndarray:
    """float32 copy with NaN where the renderer hit nothing (inf), or outside [near, far]."""
    z = np.array(depth_m, dtype=np.float32, copy=True)
    z[~np.isfinite(z) | (z < near_m) | (z > far_m)] = np.nan
    return z


def silhouette_mask(depth_m: np.ndarray, threshold_m: float) -> np.ndarray:
    """True where a 4-neighbour's depth differs by more than ``threshold_m`` or is NaN
    while the pixel is valid (both sides of a depth edge are marked)."""
    z = np.asarray(depth_m)
    mask = jumps_along(z, 0, threshold_m) | jumps_along(z, 1, threshold_m)
    return mask & np.isfinite(z)


def jumps_along(depth_m: np.ndarray, axis: int, threshold_m: float) -> np.ndarray:
    """True where the depth of a neighbour along ``axis`` (0: the pixel above or below,
    1: left or right) differs by more than ``threshold_m`` or either is NaN."""
    z = np.moveaxis(np.asarray(depth_m), axis, 0)
    mask = np.zeros(z.shape, bool)
    with np.errstate(invalid="ignore"):
        jump = ~(np.abs(z[1:] - z[:-1]) <= threshold_m)  # NaN counts as a jump
    mask[1:] |= jump
    mask[:-1] |= jump
    return np.moveaxis(mask, 0, axis)


def strided_silhouette_mask(rows_m: np.ndarray, columns_m: np.ndarray, stride: int,
                            threshold_m: float) -> np.ndarray:
    """:func:`silhouette_mask` of the full-resolution image at the pixels that
    ``subsample(., stride)`` keeps, from ``rows_m`` (the kept rows at full width) and
    ``columns_m`` (the kept columns at full height), both through
    :func:`invalidate_no_hits`."""
    across = jumps_along(rows_m, 1, threshold_m)[:, ::stride]
    down = jumps_along(columns_m, 0, threshold_m)[::stride, :]
    return (across | down) & np.isfinite(rows_m[:, ::stride])


def corrupt_depth(clean_m: np.ndarray, config: CameraConfig, seed: int, index: int,
                  columns_m: np.ndarray | None = None) -> np.ndarray:
    """The sensor model applied to a noise-free depth render (m); returns float32, NaN =
    invalid. Depends only on (clean image(s), config, seed, index). With
    ``render_stride`` s > 1, ``clean_m`` holds the kept rows at full width and
    ``columns_m`` the kept columns at full height (``DepthCameraSystem``), and the result
    is the subsampled image."""
    z = invalidate_no_hits(clean_m, config.near_m, config.far_m)
    if columns_m is None:
        silhouettes = silhouette_mask(z, config.silhouette_threshold_m)
    else:
        columns = invalidate_no_hits(columns_m, config.near_m, config.far_m)
        silhouettes = strided_silhouette_mask(z, columns, config.render_stride,
                                              config.silhouette_threshold_m)
        z = z[:, ::config.render_stride]
    rng = counter_generator(seed, index, CAMERA_STREAM)
    noise = rng.standard_normal(z.shape, dtype=np.float32)
    dropout = rng.random(z.shape, dtype=np.float32) < config.dropout_probability
    sigma = np.float32(config.noise_sigma0_m) + np.float32(config.noise_k_per_m) * z * z
    noisy = z + sigma * noise
    noisy[silhouettes | dropout] = np.nan
    return noisy


class DepthCameraSystem(LeafSystem):
    """Samples a depth image at the camera rate and delivers it, corrupted, after a delay.

    .. pydrake_system::

        name: DepthCameraSystem
        input_ports:
        - depth_image_32f
        output_ports:
        - depth_frame

    ``depth_image_32f`` is the noise-free render (``ImageDepth32F``, e.g. RgbdSensor's
    ``depth_image_32f``); it is evaluated only at capture instants (``capture_schedule``).
    With ``render_stride`` s > 1 it renders the kept rows at full width
    (``depth_render_camera(config, strides=(1, s))``), and a second input,
    ``depth_image_32f_columns``, the kept columns at full height (strides (s, 1)).
    ``depth_frame`` is the latest image that has *arrived* (``capture + delay_s``) as a
    :class:`DepthFrame` (float32 m, NaN = invalid; full resolution, or subsampled by
    ``render_stride``: ``intrinsics``), and ``DepthFrame.empty()`` before the first
    arrival; it changes only at arrivals.

    Abstract state: the frames in flight (captured, not yet arrived), oldest first, and
    the latest arrived frame. One handler serves the capture and the arrival events.
    """

    def __init__(self, config: CameraConfig, seed: int = 0, encoder_period_s: float = 1e-3):
        super().__init__()
        self._config = config
        self._seed = int(seed)
        self._period = 1.0 / config.rate_hz
        self._delay = float(config.delay_s)
        self._offsets, self._cycle = capture_schedule(config, seed, encoder_period_s)
        self._intrinsics = rendered_intrinsics(config)
        self.DeclareAbstractInputPort("depth_image_32f", AbstractValue.Make(ImageDepth32F()))
        self._columns = None
        if config.render_stride > 1:
            self._columns = self.DeclareAbstractInputPort(
                "depth_image_32f_columns", AbstractValue.Make(ImageDepth32F()))
        self._pending = self.DeclareAbstractState(AbstractValue.Make(()))
        self._latest = self.DeclareAbstractState(AbstractValue.Make(DepthFrame.empty()))
        self.DeclareAbstractOutputPort(
            "depth_frame", lambda: AbstractValue.Make(DepthFrame.empty()), self._calc_frame,
            {self.abstract_state_ticket(self._latest)})
        arrivals = (self._offsets + self._delay) % self._cycle
        event_offsets = np.sort(np.concatenate([self._offsets, arrivals]))
        distinct = np.concatenate([[True], np.diff(event_offsets) > TIME_TOLERANCE_S])
        if event_offsets[-1] > self._cycle - TIME_TOLERANCE_S and event_offsets[0] < 1e-12:
            distinct[-1] = False  # the same instant as offset 0 of the next cycle
        for offset in event_offsets[distinct]:
            self.DeclarePeriodicUnrestrictedUpdateEvent(self._cycle, float(offset),
                                                        self._on_tick)

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """Intrinsics of the delivered images (full resolution, or subsampled by
        ``render_stride``)."""
        return self._intrinsics

    @property
    def period_s(self) -> float:
        """The nominal time between captures (s): 1 / ``rate_hz``."""
        return self._period

    def _capture_index(self, t: float) -> int | None:
        """The frame captured at ``t``, or None when ``t`` is not a capture instant."""
        cycle = int(np.floor((t + TIME_TOLERANCE_S) / self._cycle))
        within = t - cycle * self._cycle
        slot = int(np.argmin(np.abs(self._offsets - within)))
        if abs(self._offsets[slot] - within) > TIME_TOLERANCE_S:
            return None
        return cycle * len(self._offsets) + slot

    def _on_tick(self, context, state):
        t = context.get_time()
        pending = list(context.get_abstract_state(self._pending).get_value())
        latest = context.get_abstract_state(self._latest).get_value()
        k = self._capture_index(t)
        if k is not None:
            image = self.get_input_port(0).Eval(context)
            clean = np.asarray(image.data)[:, :, 0]
            columns = (None if self._columns is None
                       else np.asarray(self._columns.Eval(context).data)[:, :, 0])
            depth = corrupt_depth(clean, self._config, self._seed, k, columns)
            pending.append(DepthFrame(t, t + self._delay, depth, k))
        while pending and pending[0].arrival_time_s <= t + 1e-9:
            latest = pending.pop(0)
        state.get_mutable_abstract_state(self._pending).set_value(tuple(pending))
        state.get_mutable_abstract_state(self._latest).set_value(latest)

    def _calc_frame(self, context, output):
        output.set_value(context.get_abstract_state(self._latest).get_value())


def AddDepthCamera(builder: DiagramBuilder, scene_graph: SceneGraph, parent_frame_id: FrameId,
                   config: CameraConfig, seed: int = 0, name: str = "depth_camera",
                   encoder_period_s: float = 1e-3) -> tuple[RgbdSensor, DepthCameraSystem]:
    """Adds an RgbdSensor rigidly attached at the origin of the geometry frame
    ``parent_frame_id`` (Drake camera axes: +z forward, +x right, +y down) and the
    :class:`DepthCameraSystem` that samples, corrupts and delays its depth images. With
    ``render_stride`` s > 1 the sensor renders the kept rows, and a second one
    (``NAME_rgbd_columns``, returned by neither) the kept columns. The curved shapes
    registered with a perception role so far are given meshes for the renderer
    (``config.curved_surface_tolerance_m``, :mod:`drake_tracker.sim.curved_shapes`)."""
    ensure_vtk_renderer(scene_graph)
    tessellate_curved_perception(scene_graph, config.curved_surface_tolerance_m)
    s = config.render_stride
    grids = {"": (1, s)}  # (column stride, row stride)
    if s > 1:
        grids["_columns"] = (s, 1)
    sensors = {}
    for suffix, strides in grids.items():
        sensors[suffix] = builder.AddNamedSystem(
            f"{name}_rgbd{suffix}", RgbdSensor(parent_frame_id, RigidTransform(),
                                               depth_render_camera(config, strides=strides)))
        builder.Connect(scene_graph.get_query_output_port(),
                        sensors[suffix].query_object_input_port())
    camera = builder.AddNamedSystem(name, DepthCameraSystem(config, seed, encoder_period_s))
    for suffix, sensor in sensors.items():
        builder.Connect(sensor.depth_image_32F_output_port(),
                        camera.GetInputPort(f"depth_image_32f{suffix}"))
    return sensors[""], camera

"""vpcal: calibrate fixed traffic cameras from the vanishing points of the vehicles they see.

The Python face of the vpcal library (the same pipeline, files and messages as the ``vpcal``
command line)::

    import vpcal
    cal = vpcal.calibrate("clip.mp4", detector="motion", progress=True)
    print(cal.focal_px, cal.focal_source, cal.horizon)
    cal.save("calib.json")

- :func:`calibrate`: a video, an image folder, an image, or frames in memory (numpy arrays
  H x W x 3, uint8, RGB) to a :class:`Calibration`.
- :func:`aggregate`: per-vehicle vanishing points (a VPout file, or numpy arrays) to a
  :class:`Calibration`, as ``vpcal aggregate``.
- :class:`Calibration`: focal length, K, R, rvec/tvec, VPs, horizon, confidence, evidence,
  warnings; road points in metres and back (:meth:`Calibration.road_points`,
  :meth:`Calibration.pixels`, :meth:`Calibration.distances`); tracks with speeds.
- :class:`Detector` and :class:`Network`: the pipeline's vehicle detector and VP network on
  your own frames, crops or boxes.

Errors are :class:`VpcalError` (with the CLI's message) or :class:`NotCalibrated` (the run
worked, the footage could not support a camera: the CLI's exit code 3). Long work releases the
GIL; ``progress`` takes ``True`` (a tqdm bar), a tqdm-like object or a callable.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, fields
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import NotCalibrated, VpcalError

__all__ = [
    "Calibration",
    "Detector",
    "Network",
    "NotCalibrated",
    "Options",
    "Track",
    "VpcalError",
    "aggregate",
    "calibrate",
    "load",
]

__version__ = "0.1.0"

PathLike = Union[str, "os.PathLike[str]"]
Frames = Union[np.ndarray, Iterable[np.ndarray]]
Progress = Union[bool, None, Callable[[int, Optional[int], int], Any], Any]


@dataclass
class Options:
    """The settings of :func:`calibrate`: the ``vpcal calibrate`` flags by their Python names.

    ``None`` keeps the CLI's default (given in brackets). A plain dataclass, so it pickles
    (batch engines send it to their worker processes).

    - Frames: ``every`` (1), ``max_frames`` (all), ``start`` (a frame index, or ``"4.5s"``),
      ``fps`` (a folder's or in-memory frames' rate: they are then consecutive frames; without
      it they are stills of one camera; a video has its own rate).
    - Vehicles: ``detector`` (``"auto"``: the built-in learned YOLOX-nano; ``"yolox"``,
      ``"motion"``, ``"file:PATH"``, ``"yolox:PATH"``, ``"onnx:PATH"``), ``tiles``,
      ``tile_rotation`` (False: every tile in every frame), ``onnx_layout`` (``"yolo"``),
      ``motorcycles`` (False), ``road_mask`` (a PNG path, motion detector), ``min_score``
      (0.1), ``keep_static`` (False), ``max_per_frame`` (10).
    - Network: ``model`` (the bundled one), ``device`` (``"cpu"``), ``batch`` (32),
      ``flip_average`` (False), ``min_crop_px`` (0: boxes smaller than this are cut with the
      road around them, ``--min-crop-px``), ``crops`` (``"auto"``: a few boxes per followed
      vehicle above 960 px wide, every box below; ``"all"``, ``"few"``).
    - Aggregation: ``method`` (``"robust"``, ``"robust-network"``, ``"reference"``),
      ``edgelets`` (True), ``replay`` (True), ``bootstrap`` (30), ``pp`` (``"centre"``,
      ``"bcs"`` or ``(x, y)``), ``focal`` (a known focal length, pixels), ``focal_range``
      (``(short, long)`` pixels: the focal lengths the camera can have, instead of 15-90°
      views).
    - Scale and outputs: ``scale_points`` ``(x1, y1, x2, y2)`` and ``scale_distance`` (metres)
      give the metric scale; ``tracks`` (False) computes the vehicle tracks (speeds with a
      scale); ``vehicles`` (False) keeps the per-vehicle VP records; ``overlay`` (False) keeps
      the overlay picture (``--overlay``'s PNG: :attr:`Calibration.overlay_png`), which
      :meth:`Calibration.report` then shows.
    """

    model: Optional[str] = None
    device: Optional[str] = None
    batch: Optional[int] = None
    flip_average: Optional[bool] = None
    min_crop_px: Optional[float] = None
    edgelets: Optional[bool] = None
    replay: Optional[bool] = None
    every: Optional[int] = None
    max_frames: Optional[int] = None
    fps: Optional[float] = None
    start: Optional[Union[int, str]] = None
    detector: Optional[str] = None
    tiles: Optional[int] = None
    tile_rotation: Optional[bool] = None
    onnx_layout: Optional[str] = None
    motorcycles: Optional[bool] = None
    road_mask: Optional[str] = None
    min_score: Optional[float] = None
    keep_static: Optional[bool] = None
    max_per_frame: Optional[int] = None
    crops: Optional[str] = None
    method: Optional[str] = None
    bootstrap: Optional[int] = None
    pp: Optional[Union[str, Tuple[float, float]]] = None
    focal: Optional[float] = None
    focal_range: Optional[Tuple[float, float]] = None
    max_records: Optional[int] = None
    markings: Optional[Union[str, Tuple[float, float]]] = None
    scale_points: Optional[Tuple[float, float, float, float]] = None
    scale_distance: Optional[float] = None
    tracks: Optional[bool] = None
    vehicles: Optional[bool] = None
    overlay: Optional[bool] = None

    def to_dict(self) -> Dict[str, Any]:
        """The settings that are set (not None), with paths as strings."""
        out: Dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None:
                continue
            if isinstance(v, os.PathLike):
                v = os.fspath(v)
            if f.name in ("scale_points", "pp", "focal_range", "markings") and not isinstance(v, str):
                v = tuple(float(x) for x in v)
            out[f.name] = v
        return out

    def replace(self, **changes: Any) -> "Options":
        """A copy with ``changes``."""
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        for k in changes:
            if k not in d:
                raise TypeError(f"unknown option {k!r}: expected one of {', '.join(sorted(d))}")
        d.update(changes)
        return Options(**d)


def _options(options: Optional[Options], kwargs: Dict[str, Any]) -> Dict[str, Any]:
    base = options if options is not None else Options()
    if not isinstance(base, Options):
        raise TypeError(f"options: expected vpcal.Options, got {type(base).__name__}")
    return base.replace(**kwargs).to_dict()


class _TqdmAdapter:
    """Feeds the pipeline's reports to a tqdm-like bar (``update``, ``total``, ``refresh``)."""

    def __init__(self, bar: Any, close: bool) -> None:
        self.bar = bar
        self.close = close
        self.last = 0

    def __call__(self, done: int, total: Optional[int], boxes: int) -> None:
        if total is not None and getattr(self.bar, "total", None) != total:
            self.bar.total = total
            if hasattr(self.bar, "refresh"):
                self.bar.refresh()
        if done > self.last:
            self.bar.update(done - self.last)
            self.last = done
        if hasattr(self.bar, "set_postfix"):
            self.bar.set_postfix(boxes=boxes, refresh=False)

    def finish(self) -> None:
        if self.close and hasattr(self.bar, "close"):
            self.bar.close()


def _progress(progress: Progress) -> Tuple[Optional[Callable[[int, Optional[int], int], Any]], Optional[_TqdmAdapter]]:
    if progress is None or progress is False:
        return None, None
    if progress is True:
        try:
            from tqdm.auto import tqdm
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError(
                "progress=True draws a tqdm bar: pip install tqdm, or pass a callable "
                "progress(frames_done, frames_expected, vehicle_boxes)"
            ) from e
        a = _TqdmAdapter(tqdm(unit="frame", desc="vpcal"), close=True)
        return a, a
    if hasattr(progress, "update"):
        a = _TqdmAdapter(progress, close=False)
        return a, a
    if callable(progress):
        return progress, None
    raise TypeError(
        "progress: expected True, a tqdm-like bar (with update()) or a callable "
        f"progress(frames_done, frames_expected, vehicle_boxes), got {type(progress).__name__}"
    )


def _frame_tuple(index: int, frame: Any, bgr: bool) -> Tuple[int, int, bytes]:
    a = np.asarray(frame)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(
            f"frame {index}: expected an H x W x 3 array (RGB), got shape {tuple(a.shape)}"
        )
    if a.dtype != np.uint8:
        raise TypeError(f"frame {index}: expected dtype uint8 (0-255), got {a.dtype}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"frame {index}: the frame is empty ({a.shape[1]}x{a.shape[0]})")
    if bgr:
        a = a[:, :, ::-1]
    return (int(a.shape[0]), int(a.shape[1]), np.ascontiguousarray(a).tobytes())


def _frame_opener(frames: Frames, bgr: bool) -> Callable[[], Iterator[Tuple[int, int, bytes]]]:
    if isinstance(frames, np.ndarray):
        if frames.ndim == 3:
            frames = frames[np.newaxis]
        if frames.ndim != 4:
            raise ValueError(
                "frames: expected an N x H x W x 3 array, an H x W x 3 array or an iterable of "
                f"H x W x 3 arrays, got an array of shape {tuple(frames.shape)}"
            )
    try:
        iter(frames)
    except TypeError:
        raise TypeError(
            "calibrate: expected a path (video, image folder, image) or frames (an iterable of "
            f"H x W x 3 uint8 arrays), got {type(frames).__name__}"
        ) from None
    one_shot = iter(frames) is frames
    opened = [0]

    def tuples() -> Iterator[Tuple[int, int, bytes]]:
        first = None
        for i, f in enumerate(frames):
            t = _frame_tuple(i, f, bgr)
            if first is None:
                first = t[:2]
            elif t[:2] != first:
                raise ValueError(
                    f"frame {i}: {t[1]}x{t[0]} pixels, but the first frame is "
                    f"{first[1]}x{first[0]}: every frame of a camera has one size"
                )
            yield t

    def open_frames() -> Iterator[Tuple[int, int, bytes]]:
        opened[0] += 1
        if one_shot and opened[0] > 1:
            raise ValueError(
                "frames: a one-shot iterator (a generator) cannot be read twice, and the motion "
                "detector looks at its warm-up frames again: pass a list or another re-iterable "
                "collection, or replay=False"
            )
        return tuples()

    return open_frames


def calibrate(
    source: Union[PathLike, Frames],
    options: Optional[Options] = None,
    *,
    progress: Progress = None,
    bgr: bool = False,
    raise_on_failure: bool = True,
    **settings: Any,
) -> "Calibration":
    """Calibrate a fixed traffic camera from its footage, as ``vpcal calibrate``.

    Args:
        source: a video file (anything FFmpeg reads), a folder of images, one image, or frames
            in memory: an N x H x W x 3 uint8 array, or an iterable of H x W x 3 uint8 arrays
            (RGB; ``bgr=True`` for OpenCV's BGR). In-memory frames are consecutive frames when
            ``fps`` is given, else stills (as an image folder).
        options: an :class:`Options`; keyword ``settings`` override its fields (the same names).
        progress: ``True`` for a tqdm bar, a tqdm-like bar, or a callable
            ``progress(frames_done, frames_expected_or_None, vehicle_boxes)``.
        bgr: the in-memory frames are BGR (OpenCV), not RGB.
        raise_on_failure: raise :class:`NotCalibrated` when the footage supports no camera
            (default); with False, return the result without a camera (``ok`` is False, ``reason`` says why).

    Returns:
        The :class:`Calibration` (with ``tracks`` and ``vehicles`` when asked for).

    Raises:
        VpcalError: a bad setting, an unreadable input, a failing detector or network (the
            CLI's message, naming the file, field or setting).
        NotCalibrated: the run worked but the footage could not support a calibration (its
            ``calibration_file`` is the result without a camera, JSON text).
        ValueError, TypeError: a bad setting or frame (naming it and what was expected).
    """
    opts = _options(options, settings)
    callback, adapter = _progress(progress)
    try:
        if isinstance(source, (str, os.PathLike)):
            r = _native.calibrate_path(os.fspath(source), opts, callback)
        else:
            r = _native.calibrate_frames(_frame_opener(source, bgr), "frames", opts, callback)
    finally:
        if adapter is not None:
            adapter.finish()
    cal = Calibration(
        json.loads(r["calibration"]),
        tracks=json.loads(r["tracks"]) if "tracks" in r else None,
        vehicles=json.loads(r["vehicles"]) if "vehicles" in r else None,
        run_warnings=list(r["warnings"]),
        overlay_png=r.get("overlay_png"),
    )
    if not r["ok"] and raise_on_failure:
        e = NotCalibrated(r["reason"])
        e.calibration_file = r["calibration"]
        raise e
    return cal


def _records_from_arrays(
    vp1: Any, vp2: Any, scores: Any, boxes: Any, frames: Any
) -> List[Dict[str, Any]]:
    v1 = np.asarray(vp1, dtype=float)
    v2 = np.asarray(vp2, dtype=float)
    if v1.ndim != 2 or v1.shape[1] != 2:
        raise ValueError(f"vp1: expected an N x 2 array of pixels, got shape {tuple(v1.shape)}")
    n = v1.shape[0]
    if v2.shape != (n, 2):
        raise ValueError(f"vp2: expected an {n} x 2 array (as vp1), got shape {tuple(v2.shape)}")

    def column(name: str, value: Any, default: float) -> np.ndarray:
        if value is None:
            return np.full(n, default)
        a = np.asarray(value, dtype=float)
        if a.shape != (n,):
            raise ValueError(f"{name}: expected {n} values (one per vehicle), got shape {tuple(a.shape)}")
        return a

    s = column("scores", scores, 1.0)
    f = column("frames", frames, 0.0)
    b = None
    if boxes is not None:
        b = np.asarray(boxes, dtype=float)
        if b.shape != (n, 4):
            raise ValueError(
                f"boxes: expected an {n} x 4 array of x0, y0, x1, y1 pixels, got shape {tuple(b.shape)}"
            )
    out = []
    for i in range(n):
        item: Dict[str, Any] = {
            "vp1": [float(v1[i, 0]), float(v1[i, 1])],
            "vp2": [float(v2[i, 0]), float(v2[i, 1])],
            "score": float(s[i]),
            "frame_cnt": float(f[i]),
        }
        if b is not None:
            x0, y0, x1, y1 = (float(x) for x in b[i])
            item["box_center"] = [(x0 + x1) / 2, (y0 + y1) / 2]
            item["box_scale"] = [(x1 - x0) / 2, (y1 - y0) / 2]
        out.append(item)
    return out


def aggregate(
    records: Union[PathLike, Sequence[Dict[str, Any]], "Calibration", None] = None,
    *,
    vp1: Any = None,
    vp2: Any = None,
    scores: Any = None,
    boxes: Any = None,
    frames: Any = None,
    method: Optional[str] = None,
    pp: Optional[Union[str, Tuple[float, float]]] = None,
    image_size: Optional[Tuple[int, int]] = None,
    min_score: Optional[float] = None,
    bootstrap: Optional[int] = None,
    focal: Optional[float] = None,
    focal_range: Optional[Tuple[float, float]] = None,
) -> "Calibration":
    """Per-vehicle vanishing points to a :class:`Calibration`, as ``vpcal aggregate``.

    Either ``records``: a VPout file (the reference's ``VPout_*.json`` or ``calibrate
    --vehicles``), a list of VPout items (dicts), or a :class:`Calibration` run with
    ``vehicles=True``; or numpy arrays: ``vp1`` and ``vp2`` (N x 2, frame pixels), with optional
    ``scores`` (N; default 1), ``boxes`` (N x 4: x0, y0, x1, y1 pixels) and ``frames`` (N, the
    frame of each vehicle; default 0: no tracks). Arrays need ``image_size`` (width, height).

    The settings are the CLI's (None: its default): ``method`` ("robust"), ``pp`` ("centre",
    "bcs" or (x, y)), ``image_size`` (inferred from a file's boxes), ``min_score`` (0.1),
    ``bootstrap`` (30), ``focal`` (a known focal length, pixels), ``focal_range``
    (``(short, long)`` pixels, the focal lengths the camera can have).

    Raises:
        VpcalError: an unreadable or malformed file (naming the item and field), an unknown
            frame size.
        NotCalibrated: the records support no camera.
    """
    settings: Dict[str, Any] = {}
    for k, v in (
        ("method", method),
        ("pp", pp),
        ("image_size", image_size),
        ("min_score", min_score),
        ("bootstrap", bootstrap),
        ("focal", focal),
        ("focal_range", focal_range),
    ):
        if v is not None:
            tupled = ("pp", "image_size", "focal_range")
            settings[k] = tuple(v) if k in tupled and not isinstance(v, str) else v
    arrays = vp1 is not None or vp2 is not None
    if arrays:
        if records is not None:
            raise TypeError("aggregate: give records or vp1/vp2 arrays, not both")
        if vp1 is None or vp2 is None:
            raise TypeError("aggregate: vp1 and vp2 go together")
        if image_size is None:
            raise TypeError("aggregate: arrays need image_size=(width, height)")
        items = _records_from_arrays(vp1, vp2, scores, boxes, frames)
        text = _native.aggregate("<arrays>", settings, json.dumps(items))
    elif isinstance(records, (str, os.PathLike)):
        text = _native.aggregate(os.fspath(records), settings, None)
    elif isinstance(records, Calibration):
        if records.vehicles is None:
            raise ValueError("aggregate: this calibration has no vehicle records (calibrate with vehicles=True)")
        text = _native.aggregate("<vehicles>", settings, json.dumps(records.vehicles))
    elif records is not None:
        text = _native.aggregate("<records>", settings, json.dumps(list(records), allow_nan=True))
    else:
        raise TypeError("aggregate: give records (a VPout file or items) or vp1/vp2 arrays")
    return Calibration(json.loads(text))


@dataclass
class Track:
    """One vehicle's track: image points (the box's bottom centre, where it meets the road),
    and with a metric scale road points in metres, a speed, the lane (1, 2, ... across the
    road) and the direction (``towards_vp1``/``from_vp1``)."""

    id: int
    frames: np.ndarray
    time_s: np.ndarray
    image_points: np.ndarray
    clipped: np.ndarray
    road_points: Optional[np.ndarray]
    speed_kmh: Optional[float]
    speed_uncertainty_kmh: Optional[float]
    speed_fit_kmh: Optional[float]
    lateral_m: Optional[float]
    lane: Optional[int]
    direction: Optional[str]

    @staticmethod
    def _from_json(t: Dict[str, Any]) -> "Track":
        def arr(k: str) -> np.ndarray:
            return np.array([np.nan if v is None else v for v in t[k]], dtype=float)

        road = None
        if t.get("road_x_m") is not None:
            road = np.stack([arr("road_x_m"), arr("road_y_m")], axis=1)
        return Track(
            id=int(t["id"]),
            frames=np.array(t["frames"], dtype=np.int64),
            time_s=arr("time_s"),
            image_points=np.stack([arr("x_px"), arr("y_px")], axis=1),
            clipped=np.array(t["clipped"], dtype=bool),
            road_points=road,
            speed_kmh=t.get("speed_kmh"),
            speed_uncertainty_kmh=t.get("speed_uncertainty_kmh"),
            speed_fit_kmh=t.get("speed_fit_kmh"),
            lateral_m=t.get("lateral_m"),
            lane=t.get("lane"),
            direction=t.get("direction"),
        )


def _point(v: Any) -> Optional[np.ndarray]:
    return None if v is None else np.array([np.nan if x is None else x for x in v], dtype=float)


class Calibration:
    """A calibration: the ``vpcal-calibration/2`` file of the CLI (``to_dict()``), with numpy
    views of its camera and measurements on the road.

    ``ok`` is False for a result without a camera (``reason`` says why; the camera fields
    are then None).
    """

    def __init__(
        self,
        doc: Dict[str, Any],
        *,
        tracks: Optional[Dict[str, Any]] = None,
        vehicles: Optional[List[Dict[str, Any]]] = None,
        run_warnings: Optional[List[str]] = None,
        overlay_png: Optional[bytes] = None,
    ) -> None:
        self._doc = doc
        self._tracks = tracks
        self.vehicles: Optional[List[Dict[str, Any]]] = vehicles
        """Per-vehicle VP records (VPout items) when calibrated with ``vehicles=True``."""
        self.run_warnings: List[str] = run_warnings or []
        """What the run said about its input (a truncated video, ...)."""
        self.overlay_png: Optional[bytes] = overlay_png
        """The overlay picture (PNG bytes, as ``calibrate --overlay`` writes it) when calibrated
        with ``overlay=True``."""
        self._camera: Optional[Any] = None

    def __getstate__(self) -> Dict[str, Any]:
        # The native camera is rebuilt on demand (it does not pickle).
        d = self.__dict__.copy()
        d["_camera"] = None
        return d

    # -- the file ---------------------------------------------------------------------------
    def to_dict(self) -> Dict[str, Any]:
        """The calibration file as a dict (a copy): every field ``calib.json`` has."""
        return json.loads(json.dumps(self._doc))

    def _text(self) -> str:
        return json.dumps(self._doc)

    def save(self, path: PathLike) -> None:
        """Write the calibration file (strict JSON, atomically), byte for byte as the CLI."""
        _native.write_calibration(self._text(), os.fspath(path))

    def report(self, path: Optional[PathLike] = None) -> str:
        """The self-contained HTML report of this calibration, as ``vpcal calibrate --report``
        writes it (written to ``path``, atomically, when given); returns the page.

        It always holds the focal length with its interval and sources, the horizon, the
        evidence for VP1, the metric scale, the run's settings and every warning with what to
        do about it. The picture is included when this calibration holds it (calibrated with
        ``overlay=True``), the tracks table and speed histogram when it holds tracks
        (``tracks=True``); a calibration read from a file (:meth:`load`) has neither. The page
        needs no network: the picture is inlined, the plots are inline SVG.
        """
        html = _native.render_report(
            self._text(),
            None if self._tracks is None else json.dumps(self._tracks),
            self.overlay_png,
            list(self.run_warnings),
        )
        if path is not None:
            _native.write_report(os.fspath(path), html)
        return html

    @staticmethod
    def load(path: PathLike) -> "Calibration":
        """Read a calibration file (any version vpcal reads)."""
        return Calibration(json.loads(_native.read_calibration(os.fspath(path))))

    def __repr__(self) -> str:
        if not self.ok:
            return f"Calibration(not calibrated: {self.reason})"
        return (
            f"Calibration({self.status}, focal_px={self.focal_px:.1f} ({self.focal_source}), "
            f"horizon {self.horizon_angle_deg:.2f}°, {self.image_size[0]}x{self.image_size[1]})"
        )

    # -- fields -----------------------------------------------------------------------------
    @property
    def ok(self) -> bool:
        """Whether there is a camera: ``status`` is ``calibrated``, ``rough`` or ``unreliable``
        (see :attr:`status`)."""
        return self._doc.get("status") in ("calibrated", "rough", "unreliable")

    @property
    def status(self) -> str:
        """``calibrated`` (every plausibility check passed), ``rough`` (a result is atypical
        of traffic cameras or traffic: read :attr:`warnings`), ``unreliable`` (a result is
        impossible: do not measure with it) or ``not_enough_evidence`` (no camera)."""
        return str(self._doc.get("status"))

    @property
    def reason(self) -> Optional[str]:
        """Why there is no camera, for a result without one."""
        return self._doc.get("reason")

    @property
    def image_size(self) -> Tuple[int, int]:
        w, h = self._doc["image_size"]
        return int(w), int(h)

    @property
    def focal_px(self) -> Optional[float]:
        """The focal length, pixels."""
        return self._doc.get("focal_px")

    @property
    def focal_source(self) -> Optional[str]:
        """Where the focal length came from: edgelets, network, network_rays (the VP2 rays
        within the physical prior), given, prior (assumed) or per_vehicle_median."""
        return self._doc.get("focal_source")

    @property
    def focal_interval_px(self) -> Optional[Tuple[float, float]]:
        """The 68 % interval of the focal length (for an assumed one: the plausible range)."""
        v = self._doc.get("focal_interval_px")
        return None if v is None else (v[0], v[1])

    @property
    def pp(self) -> Optional[np.ndarray]:
        """The principal point, pixels."""
        return _point(self._doc.get("pp"))

    @property
    def K(self) -> Optional[np.ndarray]:
        """The 3 x 3 camera matrix."""
        v = self._doc.get("K")
        return None if v is None else np.array(v, dtype=float)

    @property
    def R(self) -> Optional[np.ndarray]:
        """The 3 x 3 rotation: its columns are the directions of VP1, VP2, VP3 in the camera."""
        v = self._doc.get("R")
        return None if v is None else np.array(v, dtype=float)

    @property
    def rvec(self) -> Optional[np.ndarray]:
        """OpenCV rotation vector of the road frame (``cv2.projectPoints``)."""
        cv = self._doc.get("opencv")
        return None if cv is None else np.array(cv["rvec"], dtype=float)

    @property
    def tvec(self) -> Optional[np.ndarray]:
        """OpenCV translation of the road frame (metres with a scale, else road units)."""
        cv = self._doc.get("opencv")
        return None if cv is None else np.array(cv["tvec"], dtype=float)

    @property
    def dist_coeffs(self) -> Optional[np.ndarray]:
        cv = self._doc.get("opencv")
        return None if cv is None else np.array(cv["dist_coeffs"], dtype=float)

    @property
    def vp1(self) -> Optional[np.ndarray]:
        """The vanishing point of the traffic direction, pixels."""
        return _point(self._doc.get("vp1"))

    @property
    def vp2(self) -> Optional[np.ndarray]:
        """The vanishing point across the traffic, pixels."""
        return _point(self._doc.get("vp2"))

    @property
    def vp3(self) -> Optional[np.ndarray]:
        return _point(self._doc.get("vp3"))

    @property
    def horizon(self) -> Optional[np.ndarray]:
        """The horizon line (a, b, c): a x + b y + c = 0 with a² + b² = 1."""
        h = self._doc.get("horizon")
        return None if h is None else np.array(h["line"], dtype=float)

    @property
    def horizon_angle_deg(self) -> Optional[float]:
        h = self._doc.get("horizon")
        return None if h is None else h["angle_deg"]

    def horizon_y(self, x: Any) -> np.ndarray:
        """The horizon's y at image columns ``x`` (for plotting it)."""
        a, b, c = self.horizon
        return -(a * np.asarray(x, dtype=float) + c) / b

    @property
    def confidence(self) -> Optional[Dict[str, Any]]:
        """The bootstrap's spread (focal percentiles, horizon and VP1 spread), or None."""
        return self._doc.get("confidence")

    @property
    def evidence(self) -> Optional[Dict[str, Any]]:
        """What the aggregation used (counts, tracks, edgelets)."""
        return self._doc.get("evidence")

    @property
    def warnings(self) -> List[str]:
        """What a user should know about this calibration (e.g. an assumed focal length)."""
        return list(self._doc.get("warnings") or [])

    @property
    def summary(self) -> Optional[str]:
        return self._doc.get("summary")

    @property
    def scale(self) -> Optional[float]:
        """Metres per road unit, once a known distance gave it."""
        return self._doc.get("scale_m_per_unit")

    @property
    def camera_height_m(self) -> Optional[float]:
        return self._doc.get("camera_height_m")

    @property
    def camera_height_interval_m(self) -> Optional[Tuple[float, float]]:
        """68 % interval of ``camera_height_m`` with an automatic scale (the cars' sizes and
        the focal length's interval together); ``None`` otherwise."""
        iv = self._doc.get("camera_height_interval_m")
        return None if iv is None else (float(iv[0]), float(iv[1]))

    @property
    def tracks(self) -> Optional[List[Track]]:
        """The vehicle tracks, when calibrated with ``tracks=True`` (speeds need a scale)."""
        if self._tracks is None:
            return None
        return [Track._from_json(t) for t in self._tracks["tracks"]]

    @property
    def tracks_note(self) -> Optional[str]:
        """Why the tracks have no speeds, when they have none."""
        return None if self._tracks is None else self._tracks.get("note")

    # -- the road ---------------------------------------------------------------------------
    def _road(self) -> Any:
        if self._camera is None:
            self._camera = _native.RoadCamera(self._text())
        return self._camera

    def with_scale(
        self,
        points: Optional[Sequence[float]] = None,
        distance: Optional[float] = None,
        *,
        distances: Sequence[Tuple[Sequence[float], float]] = (),
        lane_widths: Sequence[Tuple[Sequence[float], float]] = (),
        keep_focal: bool = False,
    ) -> "Calibration":
        """A copy with the metric scale of known lengths on the road, as ``vpcal scale``:
        ``points`` (x1, y1, x2, y2 pixels) ``distance`` metres apart, more such pairs in
        ``distances``, and ``lane_widths``: pairs of pixels on two neighbouring lane lines
        with the lane's width (only the part across the road counts). Several give their
        geometric mean. Lengths in two directions (along and across the road) also measure
        the focal length (``focal_source`` ``distances``), unless ``keep_focal``."""
        def pair(p: Sequence[float], name: str) -> Tuple[float, float, float, float]:
            t = tuple(float(v) for v in p)
            if len(t) != 4:
                raise ValueError(f"{name}: expected x1, y1, x2, y2 (4 numbers), got {len(t)}")
            return t  # type: ignore[return-value]

        known = [(pair(p, "distances"), float(d)) for p, d in distances]
        if (points is None) != (distance is None):
            raise TypeError("with_scale: points and distance go together")
        if points is not None:
            known.insert(0, (pair(points, "points"), float(distance)))  # type: ignore[arg-type]
        widths = [(pair(p, "lane_widths"), float(w)) for p, w in lane_widths]
        if not known and not widths:
            raise TypeError("with_scale: give points and distance, distances or lane_widths")
        text = _native.set_scale(self._text(), known, widths, keep_focal)
        return Calibration(
            json.loads(text),
            tracks=self._tracks,
            vehicles=self.vehicles,
            run_warnings=self.run_warnings,
            overlay_png=self.overlay_png,
        )

    def road_points(self, pixels: Any) -> np.ndarray:
        """Road-frame points (N x 2: x along the traffic, y across, origin under the camera;
        metres with a scale, road units without) of image points (N x 2 pixels); NaN rows for
        pixels above the horizon."""
        p = _points(pixels, "pixels")
        out = self._road().road_points([(float(x), float(y)) for x, y in p])
        return _rows(out, len(p))

    def pixels(self, road_points: Any) -> np.ndarray:
        """Image points (N x 2 pixels) of road-frame points (N x 2, as :meth:`road_points`
        gives them); NaN rows behind the camera."""
        q = _points(road_points, "road_points")
        out = self._road().pixels([(float(x), float(y)) for x, y in q])
        return _rows(out, len(q))

    def distances(self, pairs: Any) -> np.ndarray:
        """Road distances (metres with a scale) between pixel pairs (N x 4: x1, y1, x2, y2), as
        ``vpcal measure``; NaN where a pixel does not see the road."""
        a = np.asarray(pairs, dtype=float)
        if a.ndim == 1:
            a = a[np.newaxis]
        if a.ndim != 2 or a.shape[1] != 4:
            raise ValueError(f"pairs: expected N x 4 (x1, y1, x2, y2), got shape {tuple(a.shape)}")
        out = self._road().distances([tuple(float(v) for v in r) for r in a])
        return np.array([np.nan if d is None else d for d in out], dtype=float)


def _points(p: Any, name: str) -> np.ndarray:
    a = np.asarray(p, dtype=float)
    if a.ndim == 1 and a.shape[0] == 2:
        a = a[np.newaxis]
    if a.ndim != 2 or a.shape[1] != 2:
        raise ValueError(f"{name}: expected N x 2 points, got shape {tuple(a.shape)}")
    return a


def _rows(out: List[Optional[Tuple[float, float]]], n: int) -> np.ndarray:
    r = np.full((n, 2), np.nan)
    for i, v in enumerate(out):
        if v is not None:
            r[i] = v
    return r


def load(path: PathLike) -> Calibration:
    """Read a calibration file (:meth:`Calibration.load`)."""
    return Calibration.load(path)


class Detector:
    """The pipeline's vehicle detector on your frames: ``Detector("yolox")(frame)`` gives an
    N x 5 array (x0, y0, x1, y1, score) in pixels.

    ``detector`` as :class:`Options` (``"auto"``, ``"yolox"``, ``"motion"``, ``"yolox:PATH"``,
    ``"onnx:PATH"``, ``"file:PATH"``); ``size`` the frames' (width, height) (the motion detector
    and tiles need it; default: the first frame's); ``fps`` the rate of consecutive frames
    (the motion detector needs it).
    """

    def __init__(
        self,
        detector: str = "auto",
        *,
        size: Optional[Tuple[int, int]] = None,
        fps: Optional[float] = None,
        tiles: Optional[int] = None,
        onnx_layout: Optional[str] = None,
        motorcycles: Optional[bool] = None,
        road_mask: Optional[str] = None,
        bgr: bool = False,
    ) -> None:
        self._settings = Options(
            detector=detector,
            fps=fps,
            tiles=tiles,
            onnx_layout=onnx_layout,
            motorcycles=motorcycles,
            road_mask=road_mask,
        ).to_dict()
        self._bgr = bgr
        self._native: Optional[Any] = None
        self._frames = 0
        if size is not None:
            self._open(size)

    def _open(self, size: Tuple[int, int]) -> Any:
        self._native = _native.Detector(self._settings, (int(size[0]), int(size[1])))
        return self._native

    @property
    def name(self) -> Optional[str]:
        return None if self._native is None else self._native.name

    def __call__(self, frame: np.ndarray, index: Optional[int] = None) -> np.ndarray:
        """The vehicle boxes of ``frame`` (H x W x 3 uint8); ``index`` its frame number
        (default: one more than the last)."""
        i = self._frames if index is None else int(index)
        h, w, data = _frame_tuple(i, frame, self._bgr)
        d = self._native if self._native is not None else self._open((w, h))
        boxes = d.detect(h, w, data, i)
        self._frames = i + 1
        return np.array(boxes, dtype=float).reshape(-1, 5)


class Network:
    """The VP network (the bundled model, or ``model``: weights, a checkpoint or a ``vpcal
    train`` run folder) on vehicle crops or on boxes of a frame."""

    def __init__(self, model: Optional[PathLike] = None, *, device: str = "cpu") -> None:
        self._net = _native.Network(None if model is None else os.fspath(model), device)

    @property
    def model(self) -> str:
        return self._net.model

    @property
    def input_size(self) -> int:
        return self._net.input_size

    def predict_crops(self, crops: Iterable[np.ndarray], *, bgr: bool = False) -> List[Dict[str, Any]]:
        """VPs of vehicle crops (H x W x 3 uint8, any size) in the box frame (the crop spans
        [-1, 1]²), as ``vpcal predict``: dicts with ``vp1_box``, ``vp2_box``, their spreads and
        scales."""
        t = [_frame_tuple(i, c, bgr) for i, c in enumerate(crops)]
        return self._net.predict_crops(t)

    def predict_boxes(self, frame: np.ndarray, boxes: Any, *, bgr: bool = False) -> List[Dict[str, Any]]:
        """VPs in frame pixels (``vp1``, ``vp2``) of vehicle ``boxes`` (N x 4: x0, y0, x1, y1,
        any detector's) in ``frame``, cut as the pipeline cuts them. Boxes that leave no crop
        inside the frame are left out: ``index`` says which box each result is."""
        b = np.asarray(boxes, dtype=float)
        if b.ndim == 1 and b.shape[0] == 4:
            b = b[np.newaxis]
        if b.size == 0:
            return []
        if b.ndim != 2 or b.shape[1] < 4:
            raise ValueError(f"boxes: expected N x 4 (x0, y0, x1, y1), got shape {tuple(b.shape)}")
        h, w, data = _frame_tuple(0, frame, bgr)
        return self._net.predict_boxes(h, w, data, [tuple(float(v) for v in r[:4]) for r in b])

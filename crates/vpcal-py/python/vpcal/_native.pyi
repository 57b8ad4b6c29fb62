"""Type stubs of ``vpcal._native``, the Rust module under the ``vpcal`` package.

It speaks plain Python values and JSON text (the calibration file, VPout records, tracks);
``vpcal`` wraps it with numpy arrays and classes. Frames travel as ``(height, width,
rgb_bytes)`` tuples. Long calls release the GIL.
"""

from typing import Any, Callable, Dict, Iterator, List, Optional, Tuple

BUNDLED_MODEL: str

class VpcalError(Exception):
    """An error of vpcal, with the CLI's message (naming the file, field or setting)."""

class NotCalibrated(VpcalError):
    """The footage or records could not support a calibration. The message is the reason;
    ``calibration_file`` the calibration file (JSON text) that says why."""

    calibration_file: str

ProgressCallback = Callable[[int, Optional[int], int], Any]
FrameTuple = Tuple[int, int, bytes]

def calibrate_path(
    path: str, options: Dict[str, Any], progress: Optional[ProgressCallback] = None
) -> Dict[str, Any]:
    """Run the pipeline on a video, image folder or image. Returns ``{"ok", "calibration"
    (JSON text), "reason" (when not ok), "tracks", "vehicles" (JSON text, when asked for),
    "warnings"}``."""

def calibrate_frames(
    open: Callable[[], Iterator[FrameTuple]],
    label: str,
    options: Dict[str, Any],
    progress: Optional[ProgressCallback] = None,
) -> Dict[str, Any]:
    """As :func:`calibrate_path` on frames from ``open()`` (a fresh iterator per call)."""

def aggregate(origin: str, settings: Dict[str, Any], records: Optional[str] = None) -> str:
    """Aggregate the VPout file ``origin`` (or ``records``, JSON text) into calibration file
    JSON text. Raises :class:`NotCalibrated` when the records support no camera."""

def read_calibration(path: str) -> str:
    """A calibration file as JSON text of the current version."""

def write_calibration(text: str, path: str) -> None:
    """Write calibration file JSON text to ``path`` as the CLI writes it."""

KnownLength = Tuple[Tuple[float, float, float, float], float]

def set_scale(
    text: str, distances: List[KnownLength], widths: List[KnownLength] = ..., keep_focal: bool = ...
) -> str:
    """The calibration with the metric scale of known road distances and lane widths
    (``vpcal scale``); lengths in two directions also measure the focal length unless
    ``keep_focal``."""

class RoadCamera:
    def __init__(self, text: str) -> None: ...
    @property
    def scale(self) -> Optional[float]: ...
    def road_points(self, pixels: List[Tuple[float, float]]) -> List[Optional[Tuple[float, float]]]: ...
    def pixels(self, points: List[Tuple[float, float]]) -> List[Optional[Tuple[float, float]]]: ...
    def distances(
        self, pairs: List[Tuple[float, float, float, float]]
    ) -> List[Optional[float]]: ...

class Detector:
    def __init__(self, settings: Dict[str, Any], size: Tuple[int, int]) -> None: ...
    @property
    def name(self) -> str: ...
    def detect(
        self, h: int, w: int, data: bytes, index: int
    ) -> List[Tuple[float, float, float, float, float]]: ...

class Network:
    def __init__(self, model: Optional[str] = None, device: str = "cpu") -> None: ...
    @property
    def model(self) -> str: ...
    @property
    def input_size(self) -> int: ...
    def predict_crops(self, crops: List[FrameTuple]) -> List[Dict[str, Any]]: ...
    def predict_boxes(
        self, h: int, w: int, data: bytes, boxes: List[Tuple[float, float, float, float]]
    ) -> List[Dict[str, Any]]: ...

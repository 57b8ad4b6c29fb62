"""Many cameras in parallel on Dask (``pip install "dask[distributed]"``).

A city calibrates hundreds of cameras: each is one :func:`vpcal.calibrate` call, independent of
the others. :func:`calibrate_many` hands them to a Dask cluster, by default a
``LocalCluster`` of one worker process per core with one thread each (each process runs the
network and detector on one core: ``RAYON_NUM_THREADS=1`` keeps their thread pools from
oversubscribing the machine). Give ``client`` to use a cluster you already run (a scheduler on
many machines, dask-jobqueue on HPC, Kubernetes): the same call spreads the cameras over it.

Why Dask: pure-Python wheels from PyPI (Ray's is a large native wheel that starts its own
servers), a local cluster and a distributed one behind the same ``Client``, and futures
whose results arrive as they finish. The :class:`vpcal.Options` dataclass pickles, and the
native code releases the GIL, so a worker stays responsive while it calibrates.

Each camera's result is a :class:`BatchResult`: the calibration, or the error's message
(a camera whose footage supports no calibration does not stop the others).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Callable, List, Optional, Sequence

from . import Calibration, NotCalibrated, Options, VpcalError, calibrate


@dataclass
class BatchResult:
    """One camera of a batch: its source and either its calibration or its error."""

    source: str
    calibration: Optional[Calibration]
    error: Optional[str] = None
    not_calibrated: bool = False

    @property
    def ok(self) -> bool:
        return self.calibration is not None


def calibrate_one(source: str, options: Optional[Options] = None) -> BatchResult:
    """Calibrate one camera, turning vpcal's errors into a :class:`BatchResult` (what a
    worker runs)."""
    try:
        return BatchResult(source, calibrate(source, options))
    except NotCalibrated as e:
        return BatchResult(source, None, str(e), not_calibrated=True)
    except VpcalError as e:
        return BatchResult(source, None, str(e))


def calibrate_many(
    sources: Sequence[os.PathLike | str],
    options: Optional[Options] = None,
    *,
    client: Any = None,
    n_workers: Optional[int] = None,
    on_result: Optional[Callable[[BatchResult], None]] = None,
) -> List[BatchResult]:
    """Calibrate every camera of ``sources`` (videos, image folders, images) with the same
    ``options``, in parallel on Dask; returns the results in the order of ``sources``.

    Args:
        sources: the cameras' footage.
        options: :class:`vpcal.Options` for every camera (``Options.replace`` for variants).
        client: a ``dask.distributed.Client`` to run on; default: a ``LocalCluster`` of
            ``n_workers`` processes (default: one per core), closed at the end.
        on_result: called with each result as it arrives (in completion order), e.g. to
            update a progress bar.
    """
    from dask.distributed import Client, LocalCluster, as_completed

    paths = [os.fspath(s) for s in sources]
    own = client is None
    cluster = None
    if own:
        n = n_workers or os.cpu_count() or 1
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            env={"RAYON_NUM_THREADS": "1"},
            dashboard_address=None,
        )
        client = Client(cluster)
    try:
        futures = [client.submit(calibrate_one, p, options, pure=False) for p in paths]
        index = {f.key: i for i, f in enumerate(futures)}
        results: List[Optional[BatchResult]] = [None] * len(paths)
        for f in as_completed(futures):
            r = f.result()
            results[index[f.key]] = r
            if on_result is not None:
                on_result(r)
        return [r for r in results if r is not None]
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()

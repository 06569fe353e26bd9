"""Marker study: how ArUco and AprilTag families compare, measured on the simulator.

``study_markers(out, families)`` renders one array of each family's markers through a
camera straight down at the floor and sweeps the marker side in pixels, the blur, the
sensor noise and the room light against the projector's contrast (``images``); each
image's markers are detected and compared with the truth (found, centre error, false
detections, time per frame). Then the same room is calibrated with each family's
sequence under clean, room-light and rolling-shutter conditions (``calibrations``),
against the truth. Everything goes into ``study.json`` and ``study.html`` (plots and a
recommendation drawn from the measurements). The measurements run on a local process
pool, or on a Ray or Dask cluster given its address (``executor``).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import asdict
from pathlib import Path

from calibproj.study.calibrations import CalibrationCondition, run_calibration
from calibproj.study.executor import run_all
from calibproj.study.images import measure_image
from calibproj.study.plan import DEFAULT_FAMILIES, StudyPlan

logger = logging.getLogger(__name__)

__all__ = ["DEFAULT_FAMILIES", "StudyPlan", "study_markers", "study_recordings"]


def study_markers(out: str | os.PathLike, families: tuple[str, ...] = DEFAULT_FAMILIES, *, quick: bool = False,
                  calibrations: bool = True, workers: int = 2, cluster: str | None = None,
                  force: bool = False, plan: StudyPlan | None = None) -> Path:
    """Run the study into the folder ``out`` (written as one transaction); the page's path.

    Args:
        families: marker family specs to compare (two or more).
        quick: the quick plan (``StudyPlan.quick``: fewer sweep points, one seed, the
            small room) instead of the full one.
        calibrations: also calibrate a rendered room with each family.
        workers: local processes (ignored with ``cluster``).
        cluster: ``ray://HOST:PORT``, ``ray:auto`` or ``tcp://HOST:PORT`` (Dask).
        force: replace an existing study folder.
        plan: sweeps and calibrations of one's own (overrides ``quick``).
    """
    from calibproj.formats.output_folder import OutputFolder
    from calibproj.sequence.markers import family_info
    from calibproj.study.report import write_study

    families = tuple(family_info(f).spec for f in families)  # ValueError naming an unknown family
    if len(set(families)) < 2:
        raise ValueError("a study compares at least two marker families (--families A,B)")
    plan = plan or (StudyPlan.quick() if quick else StudyPlan.full())
    folder = OutputFolder(out, force=force, signature=("study.json",)).open()
    started = time.perf_counter()
    with folder, folder.writing() as staging:
        images = run_all(measure_image, plan.image_conditions(families), workers, cluster, "image")
        tasks = [CalibrationCondition(f, c, plan.room, plan.arrays) for f in families for c in plan.calibrations]
        # A calibration uses both cores itself (decoding and detection threads).
        calibrated = run_all(run_calibration, tasks, 1, cluster, "calibration") if calibrations else []
        settings = {**asdict(plan),
                    "seconds": round(time.perf_counter() - started, 1)}
        write_study(staging, images, calibrated, families, settings)
    logger.info("study written to %s", folder.path)
    return folder.path / "study.html"


def study_recordings(out: str | os.PathLike, folders: list[str | os.PathLike], force: bool = False) -> Path:
    """The study of a user's own recordings (``calibproj.study.recordings``): two or more
    results folders of the same room, one per marker family, compared; the page's path."""
    from calibproj.formats.output_folder import OutputFolder
    from calibproj.study.recordings import compare_recordings
    from calibproj.study.report import write_recordings

    paths = [Path(f) for f in folders]
    if len(paths) < 2:
        raise ValueError("--recordings needs two results folders or more (one per marker family)")
    for path in paths:
        if not path.is_dir():
            raise FileNotFoundError(f"{path}: no such results folder")
    comparison = compare_recordings(paths)
    folder = OutputFolder(out, force=force, signature=("study.json",)).open()
    with folder, folder.writing() as staging:
        write_recordings(staging, comparison)
    return folder.path / "study.html"

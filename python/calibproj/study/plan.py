"""What the marker study measures: the image sweeps and the calibrations, for the quick
and the full study."""

from __future__ import annotations

from dataclasses import dataclass

from calibproj.study.images import ImageCondition

# The project's default ArUco dictionary, and two AprilTag families: tag25h9 draws 7
# cells across where ArUco 4x4 draws 6 and tag36h11 8, so the three show what the
# detector and what the cell size each change at small sizes.
DEFAULT_FAMILIES = ("aruco:4X4_50", "apriltag:tag25h9", "apriltag:tag36h11")
# Every sweep but "side" keeps markers at this side, pixels.
SWEEP_SIDE_PX = 20.0


@dataclass(frozen=True)
class StudyPlan:
    """Sweeps and calibrations of a study.

    Attributes:
        sides_px: marker sides of the ``side`` sweep.
        blurs_px: optical blur sigmas of the ``blur`` sweep.
        noises: sensor noise levels (grey levels) of the ``noise`` sweep.
        lights: (ambient, contrast) pairs of the ``light`` sweep (room light on, projector washed out).
        seeds: images per condition (each with other noise).
        room: scene preset of the calibrations.
        arrays: MSM arrays projected in the calibrations.
        calibrations: calibration conditions (``clean``, ``room-light``, ``rolling-15ms``).
    """

    sides_px: tuple[float, ...]
    blurs_px: tuple[float, ...]
    noises: tuple[float, ...]
    lights: tuple[tuple[float, float], ...]
    seeds: int
    room: str
    arrays: int
    calibrations: tuple[str, ...]

    @classmethod
    def quick(cls) -> StudyPlan:
        return cls(sides_px=(10, 15, 20, 30, 50), blurs_px=(0.7, 1.5, 3.0), noises=(2.0, 8.0),
                   lights=((0.05, 0.8), (0.4, 0.3)), seeds=1, room="small", arrays=8,
                   calibrations=("clean", "rolling-15ms"))

    @classmethod
    def full(cls) -> StudyPlan:
        return cls(sides_px=(8, 10, 12, 15, 20, 25, 30, 40, 60), blurs_px=(0.5, 1.0, 1.5, 2.0, 3.0),
                   noises=(1.0, 3.0, 6.0, 10.0), lights=((0.05, 0.8), (0.2, 0.5), (0.4, 0.3), (0.5, 0.2)),
                   seeds=3, room="demo", arrays=24, calibrations=("clean", "room-light", "rolling-15ms"))

    def image_conditions(self, families: tuple[str, ...]) -> list[ImageCondition]:
        conditions = []
        for family in families:
            for seed in range(self.seeds):
                conditions += [ImageCondition(family, "side", float(s), seed=seed) for s in self.sides_px]
                conditions += [ImageCondition(family, "blur", SWEEP_SIDE_PX, blur_px=float(b), seed=seed)
                               for b in self.blurs_px]
                conditions += [ImageCondition(family, "noise", SWEEP_SIDE_PX, noise_std=float(n), seed=seed)
                               for n in self.noises]
                conditions += [ImageCondition(family, "light", SWEEP_SIDE_PX, ambient=float(a), contrast=float(c),
                                              seed=seed) for a, c in self.lights]
        return conditions

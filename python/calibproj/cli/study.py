"""Studies on the simulator: `calibproj study markers` compares marker families.

For each family (--families, default aruco:4X4_50,apriltag:tag25h9,apriltag:tag36h11) it renders one
array of markers through a camera straight down at the floor and sweeps the marker side
in pixels, blur, sensor noise and room light; measures markers found, centre error
against the truth, false detections and detection time per frame; and calibrates a
rendered room with each family's sequence (clean, room light, rolling shutter) against
its truth. Writes OUT/study.html (plots, a recommendation table) and OUT/study.json.
--quick takes about 1.5 minutes on 2 cores, the full study about 10. With
--recordings A,B it compares instead two calibrations of your own room, one per family
(results folders of calibproj calibrate from videos). The
measurements run on local processes (--workers), or on a Ray or Dask cluster (--cluster
ray://HOST:PORT | ray:auto | tcp://HOST:PORT).
"""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("what", choices=["markers"], help="what to study")
    from calibproj.study.plan import DEFAULT_FAMILIES

    families = ",".join(DEFAULT_FAMILIES)
    parser.add_argument("--families", default=families, help=f"comma-separated marker families (default {families})")
    parser.add_argument("--out", required=True, metavar="DIR", help="study folder to write")
    parser.add_argument("--recordings", metavar="A,B",
                        help="instead of the simulator: results folders of calibproj calibrate of one room, one per "
                             "marker family, compared (markers per scale, fit residuals, agreement of the poses)")
    parser.add_argument("--quick", action="store_true", help="fewer sweep points, one seed, the small room")
    parser.add_argument("--no-calibrations", action="store_true", help="only the image sweeps")
    parser.add_argument("--workers", type=int, default=2, help="local processes (default 2)")
    parser.add_argument("--cluster", metavar="ADDRESS", help="ray://HOST:PORT, ray:auto or tcp://HOST:PORT (Dask)")
    parser.add_argument("--force", action="store_true", help="replace an existing study folder")


def run(args: argparse.Namespace) -> int:
    from calibproj.study import study_markers

    if args.workers < 1:
        raise ValueError("--workers must be at least 1")
    if args.cluster:
        from calibproj.study.executor import check_cluster_address

        check_cluster_address(args.cluster)
    if args.recordings:
        from calibproj.study import study_recordings

        page = study_recordings(args.out, [f.strip() for f in args.recordings.split(",") if f.strip()],
                                force=args.force)
        print(f"study: {page}")
        return 0
    families = tuple(f.strip() for f in args.families.split(",") if f.strip())
    page = study_markers(args.out, families, quick=args.quick, calibrations=not args.no_calibrations,
                         workers=args.workers, cluster=args.cluster, force=args.force)
    print(f"study: {page}")
    return 0

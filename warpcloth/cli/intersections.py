"""``warpcloth check-intersections FILE``: count, at every frame of a USD file written by warpcloth,
the pairs of cloth triangles that intersect (neighbours sharing a vertex excluded) and the collider
edges (boxes, meshes) that cross a cloth triangle, in float64 (:mod:`warpcloth.lab.intersections`).
Exits 0 when every frame is clean, 1 when some frame is not, 2 (one line) for a file that is not
one it can check: a layer refused before it is opened, or geometry that is not finite or consistent."""

from __future__ import annotations

import argparse
import json

from warpcloth.lab.intersections import check_usd

#: The exit status of a file with an intersection or a crossing in some frame.
EXIT_INTERSECTING = 1


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="a USD file written by warpcloth (warpcloth run ... --usd FILE)")
    p.add_argument(
        "--cloth",
        default="/World/Cloth",
        help="the cloth's mesh prim, or the prim over a model's pieces, checked as one cloth (default /World/Cloth)",
    )
    p.add_argument("--colliders", default="/World/Colliders", help="the colliders' scope (default /World/Colliders)")
    p.add_argument("--frames", action="store_true", help="one line per frame with its counts")
    p.add_argument("--json", action="store_true", help="the counts of every frame as JSON")


def run(args) -> int:
    report = check_usd(args.file, cloth=args.cloth, colliders=args.colliders)  # every layer checked before it is opened
    if args.json:
        print(
            json.dumps(
                {
                    "file": args.file,
                    "frames": report.frames,
                    "clean": report.clean,
                    "times": report.times,
                    "self_intersections": report.self_intersections,
                    "collider_crossings": report.collider_crossings,
                }
            )
        )
    else:
        if args.frames:
            for t, a, b in zip(report.times, report.self_intersections, report.collider_crossings):
                print(
                    f"t = {t:8.4f} s  self-intersecting triangle pairs {a:5d}  collider edges through the cloth {b:5d}"
                )
        if not args.quiet:
            print(f"{args.file}: {report.summary()}")
    return 0 if report.clean else EXIT_INTERSECTING


__all__ = ["EXIT_INTERSECTING", "add_arguments", "run"]

"""Generate test-set actors (benchmarks/README-testset.md): MuJoCo tissue takes as plain USD captures with truth.

    .venv/bin/python benchmarks/testset_generate.py val_default_2101 -o ../testset-actors/val_default_2101
    .venv/bin/python benchmarks/testset_generate.py --list

TEST actors (test_*) are generated once, when a change is finished, by whoever runs the
test set; never generate them to choose anything (README-testset.md: the rule).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def main() -> None:
    from testset.actors import ACTORS
    from testset.generate import generate_actor

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("actor", nargs="?", choices=sorted(ACTORS), help="the actor to generate")
    parser.add_argument("-o", "--output", type=Path, help="the actor folder to write (must not exist)")
    parser.add_argument("--takes", default="session,test", help="comma-separated: session, test, transfer, cross (default session,test)")
    parser.add_argument("--source-actor", choices=sorted(ACTORS), help="with --takes cross: the actor (of the same face) whose run the cross take moves like")
    parser.add_argument("--seconds-scale", type=float, default=1.0, help="scales every take's length (2 s session, 2.5 s test)")
    parser.add_argument("--jobs", type=int, default=1, help="takes simulated at a time, one core each")
    parser.add_argument("--data", type=Path, default=DATA, help="the shared data folder (ICT rig, Live Link CSVs, CMU mocap)")
    parser.add_argument("--list", action="store_true", help="list the actors and exit")
    args = parser.parse_args()
    if args.list:
        for actor in ACTORS.values():
            print(f"{actor.name}\t{actor.split}\t{actor.face}")
        return
    if args.actor is None or args.output is None:
        parser.error("give an actor and -o FOLDER (or --list)")
    which = tuple(w for w in args.takes.split(",") if w)
    if not set(which) <= {"session", "test", "transfer", "cross"} or not which:
        parser.error(f"--takes: expected session, test, transfer and/or cross, got {args.takes!r}")
    source = ACTORS[args.source_actor] if args.source_actor else None
    if "cross" in which and (source is None or source.face != ACTORS[args.actor].face or source.name == args.actor):
        parser.error("--takes cross needs --source-actor, another actor of the same face")
    if not args.seconds_scale > 0:
        parser.error("--seconds-scale must be positive")
    if not args.data.is_dir():
        sys.exit(f"{args.data}: the shared data folder is needed (Live Link curves, CMU mocap, ICT rig)")
    try:
        generate_actor(ACTORS[args.actor], args.output, args.data, which, args.seconds_scale, max(args.jobs, 1), source=source)
    except FileExistsError as error:
        sys.exit(str(error))


if __name__ == "__main__":
    main()

"""Stage ``check``: python -m stages.check SURFACE.npz TRIALS.parquet PARTS.npz SCALE HAND CHECKS.parquet
[--timing T.json] [--log L.mcap]

A seeded sample of the hand's trials per planner: the lift-and-shake checks (pybullet, MuJoCo
from the closed pose and from the open hand) and robust force closure (params ``checks``; see pipeline/checks/protocol.py).
The object's convex parts (stage ``decompose``, at one scale) are scaled to SCALE, the surface's.
"""

import dataclasses

from pipeline.stage_io import one_line_errors, params, progress_bar, stage_args, stage_run


@one_line_errors
def main(argv=None):
    from pipeline.pool import default_workers

    args = stage_args(__doc__, "surface", "trials", "parts", "scale", "hand", "checks", argv=argv)
    config = params()
    from pipeline.artefacts import SurfaceSamples, read_table, write_table
    from pipeline.checks.physics import ConvexParts
    from pipeline.checks.protocol import check_trials, summary
    from pipeline.hands.spec import get_hand

    used = {"seed": config.seed, "hand": args.hand, **dataclasses.asdict(config.checks)}
    inputs = [args.surface, args.trials, args.parts]
    with stage_run(args, "check", params=used, inputs=inputs, outputs=[args.checks]) as run:
        surface, trials, parts = (
            SurfaceSamples.load(args.surface),
            read_table(args.trials),
            ConvexParts.load(args.parts).at_scale(float(args.scale)),
        )
        with progress_bar(f"check {args.checks}", unit="check") as progress:
            checks = check_trials(
                surface,
                trials,
                parts,
                hands=[get_hand(args.hand)],
                seed=config.seed,
                settings=config.simulate,
                workers=default_workers(config.simulate.workers),
                progress=progress,
                **dataclasses.asdict(config.checks),
            )
        write_table(args.checks, checks)
        result = summary(checks)
        run.count(
            **{
                f"{planner}_{key}": value
                for planner in ("mat", "baseline")
                for key, value in result[planner].items()
                if not key.endswith("_outcomes")
            }
        )
    mat, baseline = result["mat"], result["baseline"]
    print(
        f"check {args.checks}: {len(checks)} trials, held (pybullet / MuJoCo / MuJoCo open) "
        f"{mat['physics_success_rate']:.1%} / {mat['mujoco_success_rate']:.1%} / {mat['mujoco_open_success_rate']:.1%} MAT, "
        f"{baseline['physics_success_rate']:.1%} / {baseline['mujoco_success_rate']:.1%} / "
        f"{baseline['mujoco_open_success_rate']:.1%} baseline; robust force closure {mat['robust_fc']:.2f} / {baseline['robust_fc']:.2f}"
    )


if __name__ == "__main__":
    main()

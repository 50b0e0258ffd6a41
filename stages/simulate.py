"""Stage ``simulate``: python -m stages.simulate SURFACE.npz CANDIDATES.parquet HAND TRIALS.parquet CONTACTS.parquet
[--timing T.json] [--log L.mcap] [--rrd R.rrd --recording-id ID]

The recording shows every candidate (approach arrows, P_o) and each trial on its own step of the
``trial`` timeline; the log holds one ``/trials`` message per trial.
"""

import dataclasses

from pipeline.stage_io import one_line_errors, params, progress_bar, stage_args, stage_run


@one_line_errors
def main(argv=None):
    from pipeline.pool import default_workers, start

    args = stage_args(__doc__, "surface", "candidates", "hand", "trials", "contacts", argv=argv)
    config = params()
    workers = default_workers(config.simulate.workers)
    if workers > 1:
        start()  # the trial workers' server imports the engine while this process reads its inputs
    from pipeline.artefacts import SurfaceSamples, read_table, write_table
    from pipeline.hands.spec import get_hand
    from pipeline.outputs.recording import log_candidates, record_stage
    from pipeline.outputs.trial_recording import log_trials
    from pipeline.trial.protocol import simulate, summary

    used = {"seed": config.seed, "hand": args.hand, **dataclasses.asdict(config.simulate)}
    with stage_run(
        args,
        "simulate",
        params=used,
        inputs=[args.surface, args.candidates],
        outputs=[args.trials, args.contacts],
        record=config.record,
    ) as run:
        hand = get_hand(args.hand)
        surface, candidates = SurfaceSamples.load(args.surface), read_table(args.candidates)
        with progress_bar(f"simulate {args.trials}") as progress:
            trials, contacts = simulate(
                surface,
                candidates,
                [hand],
                spheres_per_object=config.simulate.spheres_per_object,
                baseline_trials=config.simulate.baseline_trials,
                seed=config.seed,
                workers=workers,
                settings=config.simulate,
                progress=progress,
            )
        write_table(args.contacts, contacts)
        write_table(args.trials, trials)
        result = summary(trials)
        run.count(
            rows=len(trials),
            contacts=len(contacts),
            **{key: value for key, value in result.items() if key != "per_hand"},
        )  # MAT, then baseline
        if not len(candidates):
            run.warn(f"{args.candidates}: no candidates, so no trials for {args.hand}")
        if run.log:
            run.log.trials(trials)

        def draw(stream, root):
            log_candidates(stream, root, candidates)
            log_trials(stream, root, surface, hand, trials, contacts, settings=config.simulate)

        record_stage(run, draw)
    print(
        f"simulate {args.trials}: {result['trials']} MAT trials, force closure "
        f"{result['force_closure_rate']:.1%} (baseline {result['baseline']['force_closure_rate']:.1%} "
        f"of {result['baseline']['trials']})"
    )


if __name__ == "__main__":
    main()

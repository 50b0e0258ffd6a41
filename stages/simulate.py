"""Stage ``simulate``: python -m stages.simulate SURFACE.npz CANDIDATES.parquet HAND TRIALS.parquet CONTACTS.parquet
[--timing T.json]"""

from pipeline.cli import one_line_errors, params, progress_bar, stage_args, timed


@one_line_errors
def main(argv=None):
    # imported here: trial workers are spawned and re-import this module, and need none of it
    from pipeline.artefacts import SurfaceSamples, read_table, write_table
    from pipeline.hands import get_hand
    from pipeline.trials import default_workers, simulate, summary

    args = stage_args(__doc__, "surface", "candidates", "hand", "trials", "contacts", argv=argv)
    config = params()
    with timed(args.timing, "simulate"):
        hand = get_hand(args.hand)
        surface, candidates = SurfaceSamples.load(args.surface), read_table(args.candidates)
        with progress_bar(f"simulate {args.trials}") as progress:
            trials, contacts = simulate(surface, candidates, [hand],
                                        spheres_per_object=config.simulate.spheres_per_object,
                                        baseline_trials=config.simulate.baseline_trials, seed=config.seed,
                                        workers=default_workers(config.simulate.workers),
                                        settings=config.simulate.world_settings(), progress=progress)
        write_table(args.contacts, contacts)
        write_table(args.trials, trials)
    result = summary(trials)
    print(f"simulate {args.trials}: {result['trials']} MAT trials, force closure "
          f"{result['force_closure_rate']:.1%} (baseline {result['baseline']['force_closure_rate']:.1%} "
          f"of {result['baseline']['trials']})")


if __name__ == "__main__":
    main()

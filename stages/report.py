"""Stage ``report``: python -m stages.report DATA_DIR OUT_DIR [--log L.mcap]

Reads ``DATA_DIR/<object>/<scale>/<hand>/trials.parquet`` and ``checks.parquet`` of every object,
scale and hand in params.yaml and every ``timing/*.json`` beside the artefacts; writes into OUT_DIR ``report.md``,
``trials.parquet`` (every trial), ``metrics.json``, ``plots/*.csv`` and ``figures/*.png``.
"""

import dataclasses
import io
import json
from pathlib import Path

from pipeline.stage_io import one_line_errors, params, stage_args, stage_run


def run_dir(data, name, scale, hand=None):
    folder = Path(data) / name / str(scale)
    return folder / hand if hand else folder


@one_line_errors
def main(argv=None):
    from pipeline.artefacts import atomic_write, json_bytes, read_table, write_table
    from pipeline.dag import ROOT, object_stage_file
    from pipeline.errors import ArtefactError, BadParamsError
    from pipeline.outputs import report

    args = stage_args(__doc__, "data", "out", argv=argv)
    config = params()
    out = Path(args.out)
    runs = [
        (name, scale, hand) for name in config.objects for scale in config.scales for hand in config.candidates.hands
    ]
    tables, checks, timings = {}, {}, []
    for name, scale, hand in runs:
        path = run_dir(args.data, name, scale, hand) / "trials.parquet"
        if not path.is_file() and not (ROOT / object_stage_file("simulate", name)).is_file():
            raise BadParamsError(
                f"params.yaml: object {name!r} has no stage files; run `python -m pipeline.dag` to write them "
                "(make run does), then `dvc repro`"
            )
        if not path.is_file():
            raise ArtefactError(f"{path}: missing; run `dvc repro` (the report needs every simulate stage)")
        tables[(name, scale, hand)] = read_table(path)
        checks[(name, scale, hand)] = read_table(path.with_name("checks.parquet"))
    for folder in {run_dir(args.data, name, scale) for name, scale, _ in runs}:
        timings += [json.loads(path.read_text()) for path in sorted(folder.rglob("timing/*.json"))]
    used = {
        "seed": config.seed,
        "objects": list(config.objects),
        "scales": list(config.scales),
        "hands": list(config.candidates.hands),
        **dataclasses.asdict(config.report),
    }
    inputs = [run_dir(args.data, *run) / name for run in runs for name in ("trials.parquet", "checks.parquet")]
    with stage_run(args, "report", params=used, inputs=inputs) as run:
        trials = report.combine(tables, checks)
        table = report.results(trials, runs)
        metrics = report.metrics(trials, table)
        force_closure, epsilon = report.plot_tables(table, trials, bins=config.report.epsilon_bins)

        write_table(out / "trials.parquet", trials)
        for planner, frame in force_closure.items():
            atomic_write(out / "plots" / f"force_closure_{planner}.csv", lambda s, f=frame: f.to_csv(s, index=False))
        atomic_write(out / "plots" / "epsilon.csv", lambda stream: epsilon.to_csv(stream, index=False))
        calibration = report.calibration(trials)
        for score, frame in report.calibration_plots(calibration).items():
            atomic_write(out / "plots" / f"calibration_{score}.csv", lambda s, f=frame: f.to_csv(s, index=False))
        atomic_write(out / "metrics.json", lambda stream: stream.write(json_bytes(metrics, indent=2)))
        figures = write_figures(args.data, out, config, trials, calibration)
        settings = (
            f"Protocol: {config.simulate.spheres_per_object} random spheres of the reduced set per object, "
            f"scale and hand, all their candidates tried, and as many surface-normal baseline trials; "
            f"mu = {config.simulate.mu:g}, {config.simulate.cone_edges} cone edges, seed {config.seed}. "
            f"Every trial: `trials.parquet` (pandas: `pd.read_parquet`)."
        )
        text = report.markdown(table, metrics, report.timing_table(timings), figures=figures, settings=settings)
        atomic_write(out / "report.md", lambda stream: stream.write(text.encode()))
        run.count(trials=len(trials), runs=len(runs), figures=len(figures))
        run.outputs += [out / name for name in ("trials.parquet", "metrics.json", "report.md")]
        run.outputs += sorted((out / "plots").glob("*.csv")) + [out / path for _, path in figures]
    print(
        f"report {out / 'report.md'}: {len(trials)} trials in {len(runs)} runs; MAT force closure "
        f"{100 * metrics['mat']['force_closure_rate']:.1f} % vs baseline "
        f"{100 * metrics['baseline']['force_closure_rate']:.1f} %; MAT above the baseline in "
        f"{metrics['runs_mat_above_baseline']} of {metrics['runs_compared']} runs"
    )


def write_figures(data, out, config, trials, calibration):
    """PNGs of the calibration (physics success against the analytic scores) and of the objects
    named in ``report.figure_objects``: medial spheres and candidates (paper Fig. 5), and the
    best grasps of each hand (Fig. 7). Returns (caption, path) pairs."""
    import pandas as pd
    from PIL import Image

    from pipeline.artefacts import MedialSpheres, SurfaceSamples, atomic_write, read_table
    from pipeline.geometry.concavity import Concavities
    from pipeline.geometry.symmetry import Symmetry
    from pipeline.hands.spec import get_hand
    from pipeline.outputs import figures

    def save(image, name):
        buffer = io.BytesIO()
        Image.fromarray(image).save(buffer, format="PNG")
        atomic_write(out / "figures" / name, lambda stream: stream.write(buffer.getvalue()))
        return f"figures/{name}"

    captions = []
    if calibration.checked.sum():
        captions.append(
            (
                "Do the analytic scores predict holding? Physics success of the checked trials per epsilon bin "
                "and per robust force-closure bin (legend: checked trials)",
                save(figures.calibration_figure(calibration), "calibration.png"),
            )
        )
    for name in config.report.figure_objects:
        if name not in config.objects:
            continue
        for scale in config.scales:
            folder = run_dir(data, name, scale)
            candidates = [
                read_table(run_dir(data, name, scale, hand) / "candidates.parquet") for hand in config.candidates.hands
            ]
            image = figures.sphere_figure(
                MedialSpheres.load(folder / "spheres.npz"),
                Symmetry.load(folder / "symmetry.npz"),
                pd.concat(candidates, ignore_index=True),
                title=f"{name} x{scale}",
                concavities=Concavities.load(folder / "concavity.npz"),
            )
            captions.append(
                (
                    f"{name} x{scale}: medial spheres by diameter (red small, blue large); reduced set, "
                    f"e1/e2 and candidate approaches by class (crimson: encompassing a concavity)",
                    save(image, f"{name}-{scale}-spheres.png"),
                )
            )
            surface = SurfaceSamples.load(folder / "surface.npz")
            for hand_name in config.candidates.hands:
                runs = trials[
                    (trials.object == name) & (trials.scale == float(scale)) & (trials.hand == hand_name)
                ].reset_index(drop=True)
                for planner, what, suffix in (
                    ("mat", "the force-closure grasps", "grasps"),
                    ("encompassing", "the force-closure grasps encompassing its concavity", "encompassing"),
                ):
                    images = figures.grasp_images(
                        surface, get_hand(hand_name), runs, count=config.report.example_grasps, planner=planner
                    )
                    if images:
                        captions.append(
                            (
                                f"{name} x{scale}, {hand_name}: {what} with the highest epsilon",
                                save(
                                    figures.image_grid(images, len(images)), f"{name}-{scale}-{hand_name}-{suffix}.png"
                                ),
                            )
                        )
    return captions


if __name__ == "__main__":
    main()

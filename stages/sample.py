"""Stage ``sample``: python -m stages.sample OBJECT OUT.npz"""

import dataclasses

import numpy as np

from pipeline.cli import one_line_errors, params, stage_args
from pipeline.errors import BadParamsError
from pipeline.objects import parse_spec, source_key
from pipeline.sampling import sample_object


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "object", "out", argv=argv)
    config = params()
    if args.object not in config.objects:
        raise BadParamsError(f"params.yaml: no object named {args.object!r} under 'objects'")
    source, scale, shape = parse_spec(args.object, config.objects[args.object])
    surface = sample_object(source, scale=scale, shape=shape, rng=np.random.default_rng(config.seed),
                            source_key=source_key(source, shape), **dataclasses.asdict(config.sample))
    surface.save(args.out)
    print(f"sample {args.object}: {len(surface.points)} samples, spacing {surface.spacing * 1e3:.3f} mm")


if __name__ == "__main__":
    main()

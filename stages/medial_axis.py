"""Stage ``medial_axis``: python -m stages.medial_axis SURFACE.npz OUT.npz"""

import argparse
import dataclasses

from pipeline.artefacts import SurfaceSamples
from pipeline.cli import one_line_errors, params
from pipeline.medial_axis import medial_axis


@one_line_errors
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("surface")
    parser.add_argument("out")
    args = parser.parse_args(argv)
    axis = medial_axis(SurfaceSamples.load(args.surface), **dataclasses.asdict(params().medial_axis))
    axis.save(args.out)
    print(f"medial_axis {args.out}: {len(axis.radii)} balls ({axis.method})")


if __name__ == "__main__":
    main()

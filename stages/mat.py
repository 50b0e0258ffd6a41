"""Stage ``mat``: python -m stages.mat SURFACE.npz MEDIAL_AXIS.npz OUT.npz"""

import argparse
import dataclasses

from pipeline.artefacts import MedialAxis, SurfaceSamples
from pipeline.cli import one_line_errors, params
from pipeline.mat import reconstruct


@one_line_errors
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("surface")
    parser.add_argument("medial_axis")
    parser.add_argument("out")
    args = parser.parse_args(argv)
    spheres = reconstruct(SurfaceSamples.load(args.surface), MedialAxis.load(args.medial_axis),
                          **dataclasses.asdict(params().mat))
    spheres.save(args.out)
    print(f"mat {args.out}: {len(spheres)} medial spheres")


if __name__ == "__main__":
    main()

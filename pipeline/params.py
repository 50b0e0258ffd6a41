"""Typed, validated params: one frozen dataclass per ``params.yaml`` section.

These defaults are the project's single documented place for the tunable settings (numerical
tolerances of the algorithms are in :mod:`pipeline.tol`). A params file must hold every
section and key: the repository's ``params.yaml`` equals these defaults (a test proves it), so
``dvc repro``, ``plan`` and ``batch`` read the same values; ``python -m pipeline.params`` prints
them as a complete file. A missing or unknown key, or a value of the wrong type, fails with the
file, section and key in the message.
"""

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from .errors import BadParamsError

#: ``checks.engine``: which lift-and-shake checks run
ENGINES = ("pybullet", "mujoco", "both")


@dataclass(frozen=True)
class SampleParams:
    """Surface sampling (stage ``sample``)."""

    count: int = 20000
    """Number of area-uniform surface samples."""
    sharp_angle_deg: float = 30.0
    """Dihedral angle above which an edge is a crease: normals are not smoothed across it."""
    min_extent_m: float = 0.005
    """Smallest accepted bounding-box diagonal after scaling; below it the units are wrong."""
    max_extent_m: float = 5.0
    """Largest accepted bounding-box diagonal after scaling (a mesh in mm reads as 1000x too big)."""
    cloud_normal_neighbours: int = 30
    """k of the kNN plane fit when a point cloud has no normals."""

    def __post_init__(self):
        _require(self.count >= 100, "sample", "count", "must be >= 100")
        _require(0 < self.sharp_angle_deg < 180, "sample", "sharp_angle_deg", "must be in (0, 180)")
        _require(
            0 < self.min_extent_m < self.max_extent_m,
            "sample",
            "min_extent_m",
            "must be positive and below max_extent_m",
        )
        _require(self.cloud_normal_neighbours >= 5, "sample", "cloud_normal_neighbours", "must be >= 5")


@dataclass(frozen=True)
class MedialAxisParams:
    """Medial axis point cloud (stage ``medial_axis``)."""

    method: str = "shrinking_ball"
    """``shrinking_ball`` (default, Ma et al. 2012) or ``voronoi_poles`` (Qhull inner poles, reference)."""
    kdtree_eps: float = 4.0
    """Approximate-NN slack of the growing pass (exact queries stall on tubes); the
    exact polish of the merged balls restores full accuracy, so a loose slack only saves time."""
    min_chord_factor: float = 4.0
    """Stop shrinking when the two contacts are closer than this many median sample spacings."""
    min_separation_deg: float = 20.0
    """Stop shrinking when the two contacts are closer than this angle seen from the new centre."""
    max_iterations: int = 30
    merge_factor: float = 0.5
    """Balls whose centres share a voxel of this many median sample spacings (at least) merge."""
    merge_relative: float = 0.01
    """...and whose radii agree within this fraction; the voxel grows to this fraction of r."""

    def __post_init__(self):
        _require(
            self.method in ("shrinking_ball", "voronoi_poles"),
            "medial_axis",
            "method",
            f"must be 'shrinking_ball' or 'voronoi_poles', got {self.method!r}",
        )
        _require(self.kdtree_eps >= 0, "medial_axis", "kdtree_eps", "must be >= 0")
        _require(self.min_chord_factor >= 0, "medial_axis", "min_chord_factor", "must be >= 0")
        _require(0 <= self.min_separation_deg < 180, "medial_axis", "min_separation_deg", "must be in [0, 180)")
        _require(self.max_iterations >= 1, "medial_axis", "max_iterations", "must be >= 1")
        _require(self.merge_factor >= 0, "medial_axis", "merge_factor", "must be >= 0")
        _require(0 <= self.merge_relative < 1, "medial_axis", "merge_relative", "must be in [0, 1)")


@dataclass(frozen=True)
class MatParams:
    """Medial sphere reconstruction (stage ``mat``, paper II-A)."""

    tau: float = 0.01
    """A sample touches a sphere of radius r when it lies within r (1 + tau) of the centre."""
    max_contacts: int = 4
    """At most this many nearest touching samples are kept per sphere."""
    search: str = "kdtree"
    """Nearest-surface-point search: ``kdtree`` (pykdtree) or ``grid`` (the paper's cell grid)."""
    kdtree_eps: float = 0.2
    """Approximate-NN slack of the kd-tree search for touching samples (radii stay exact)."""
    cell_density: float = 4.0
    """C of eq. 1 for the ``grid`` search: expected samples per cell (4 general, 2 thin objects)."""

    def __post_init__(self):
        _require(0 <= self.tau < 1, "mat", "tau", "must be in [0, 1)")
        _require(self.max_contacts >= 2, "mat", "max_contacts", "must be >= 2")
        _require(self.search in ("kdtree", "grid"), "mat", "search", f"must be 'kdtree' or 'grid', got {self.search!r}")
        _require(self.kdtree_eps >= 0, "mat", "kdtree_eps", "must be >= 0")
        _require(self.cell_density > 0, "mat", "cell_density", "must be > 0")


@dataclass(frozen=True)
class SphereGridParams:
    """Grid of medial spheres (stage ``sphere_grid``, paper II-B)."""

    cell_density: float = 4.0
    """C of eq. 1: expected sphere centres per cell."""

    def __post_init__(self):
        _require(self.cell_density > 0, "sphere_grid", "cell_density", "must be > 0")


@dataclass(frozen=True)
class ClassifyParams:
    """Reduced set and neighbourhood PCA (stage ``classify``, paper III-A/B)."""

    min_object_angle_deg: float = 120.0
    """Spheres with a smaller object angle describe surface detail and are left out."""
    min_diameter_m: float = 0.0
    max_diameter_ratio: float = 1.0
    """Keep d <= ratio x d_max (the paper's object set 2 used 0.3); 1 keeps all."""
    search_radius: float = 0.05
    """Neighbourhood radius: a fraction of the object's bounding-box diagonal, or metres."""
    search_radius_unit: str = "relative"
    """``relative`` (scales with the object: 1 cm on a 20 cm object) or ``metres``."""
    rho_axis: float = 0.01
    rho_plane: float = 0.4
    isolated_spread: float = 0.05
    """A neighbourhood spread (sqrt l1) below this x the sphere radius is a spherical part."""
    pca_cell_fraction: float = 0.25
    """Neighbourhoods are gathered per cell of this x search radius (exact cell moments); 0 = per sphere."""

    def __post_init__(self):
        _require(0 <= self.min_object_angle_deg <= 180, "classify", "min_object_angle_deg", "must be in [0, 180]")
        _require(self.min_diameter_m >= 0, "classify", "min_diameter_m", "must be >= 0")
        _require(0 < self.max_diameter_ratio <= 1, "classify", "max_diameter_ratio", "must be in (0, 1]")
        _require(self.search_radius > 0, "classify", "search_radius", "must be > 0")
        _require(
            self.search_radius_unit in ("relative", "metres"),
            "classify",
            "search_radius_unit",
            f"must be 'relative' or 'metres', got {self.search_radius_unit!r}",
        )
        _require(
            0 < self.rho_axis < self.rho_plane <= 1,
            "classify",
            "rho_axis",
            "must satisfy 0 < rho_axis < rho_plane <= 1",
        )
        _require(self.isolated_spread >= 0, "classify", "isolated_spread", "must be >= 0")
        _require(0 <= self.pca_cell_fraction <= 1, "classify", "pca_cell_fraction", "must be in [0, 1]")


@dataclass(frozen=True)
class ConcavityParams:
    """Concavities and the grasps that encompass them (stage ``concavity``,
    :mod:`pipeline.geometry.concavity`; the paper's section V)."""

    enabled: bool = True
    """False: no concavities, no ``encompassing`` candidates (the concavity artefacts are empty)."""
    min_volume: float = 0.05
    """Smallest concavity counted, as a fraction of the object's convex hull volume."""
    flat_mouth_deg: float = 5.0
    """A concavity counts when it opens through one flat mouth (a container): every face of its
    opening within this of their mean normal."""
    max_width_ratio: float = 1.0
    """A hand gets a concavity's encompassing candidates when the concavity is at most this x the
    hand's ``max_graspable_diameter`` wide (its largest medial sphere)."""

    def __post_init__(self):
        _require(0 < self.min_volume < 1, "concavity", "min_volume", "must be in (0, 1) (x the hull's volume)")
        _require(0 < self.flat_mouth_deg < 90, "concavity", "flat_mouth_deg", "must be in (0, 90) degrees")
        _require(self.max_width_ratio > 0, "concavity", "max_width_ratio", "must be > 0")


@dataclass(frozen=True)
class CandidatesParams:
    """Candidate grasps (stage ``candidates``, paper III-C)."""

    hands: list = field(default_factory=lambda: ["armar3", "barrett"])
    """Hands to plan and simulate for: built-in names or paths to hand specs (see :mod:`pipeline.hands.spec`)."""
    approach_directions: int = 4
    """Approach directions around a symmetry axis (Simox default 4)."""
    flipped_candidates: bool = True
    """Also emit every candidate with P_o = -P_o (Simox default)."""
    centre_rims: bool = True
    """Move a rim candidate's P_g across the rim so the open hand's finger gap is centred on
    the object's material between its fingers, where it fits (a thin wall round a cavity
    narrower than the hand); false: P_g at the sphere centre, as the paper."""

    def __post_init__(self):
        from .hands.spec import HANDS, is_spec_path

        _require(
            isinstance(self.hands, list) and self.hands and all(h in HANDS or is_spec_path(h) for h in self.hands),
            "candidates",
            "hands",
            f"must list built-in hands ({', '.join(HANDS)}) or hand spec files, got {self.hands!r}",
        )
        _require(self.approach_directions >= 1, "candidates", "approach_directions", "must be >= 1")
        for key in ("flipped_candidates", "centre_rims"):
            _require(isinstance(getattr(self, key), bool), "candidates", key, "must be true or false")


@dataclass(frozen=True)
class SimulateParams:
    """Grasp trials (stage ``simulate``, paper IV; see :mod:`pipeline.trial.engine`)."""

    spheres_per_object: int = 200
    """Random spheres (with candidates) per hand; all their candidates are tried (the paper's 200)."""
    baseline_trials: int = -1
    """Surface-normal baseline trials per hand: -1 = as many as the MAT trials, 0 = none."""
    mu: float = 0.5
    """Coulomb friction coefficient; the linearised cone's half-angle is atan(mu)."""
    cone_edges: int = 8
    torsional_friction_m: float = 0.0
    """Soft-finger torsional friction (m); 0 = point contacts with friction, as in the paper."""
    contact_tolerance_m: float = 0.002
    """A link this close to the object (exact mesh distance) touches it: it stops, and its
    touching pairs are contacts."""
    retract_step_m: float = 0.005
    """Retreat step along -P_d until the hand is clear (then it comes on to contact in fine steps)."""
    retract_max_m: float = 0.2
    """A candidate whose hand is not clear after this retreat is a ``collision``."""
    approach_step_m: float = 0.001
    """Largest step of the approach to contact after the retreat; at most the contact tolerance."""
    approach_max_m: float = -1.0
    """How far past where it was placed the hand may come on along P_d looking for contact;
    a hand that travels it all without a link within the tolerance missed the object
    (``no_contact``, fingers not closed). -1 = the hand's ``max_graspable_diameter``; 0 = never
    past the placement."""
    near_m: float = 0.004
    """Distances up to this are exact mesh queries; beyond, a signed distance grid's bound sets
    the (conservative) step. At least the contact tolerance."""
    max_close_steps: int = 200
    """Closing steps before a trial whose fingers still move is given up (outcome ``step_cap``)."""
    link_point_spacing_m: float = 0.003
    """Largest gap between the points on a hand link's edges that are measured against the mesh
    while the hand moves (retreat, approach, closing)."""
    contact_point_spacing_m: float = 0.001
    """The same for the closed hand's contacts, at most ``link_point_spacing_m`` (the gaps of
    those points split evenly, so the closing points are among them). At 3 mm a link edge lying
    across a curved surface gave too few contacts: 5 of the 8 trials of the bench's sample
    where the engine and the reference disagreed."""
    coplanar_deg: float = 5.0
    """Contacts of one link whose normals agree within this angle form one region (GraspIt)."""
    max_link_contacts: int = 0
    """Most contacts kept per link (its regions' hull corners, farthest first); 0 = every corner,
    as GraspIt. A cap of 4 lost a facetted part's second facet: Barrett on the chair's legs went
    from 80 to 31 % force closure on the same closed hands."""
    grid_cells: int = 40
    """Nodes of the object's signed distance grid along its longest side (steps only)."""
    approach_to_contact: bool = True
    """After the retreat, move the hand along P_d until a link is within the contact tolerance,
    past the placement too (OpenRAVE's and GraspIt's approach to contact); false: close where
    the retreat left the hand clear, as the paper's Simox port did (``approach_m`` 0)."""
    palm_contacts: bool = True
    """Grade the palm's (the base link's) contacts with the fingers'; false: drop them before
    the quality, so a hand touching with its palm alone is ``no_contact``."""
    workers: int = 0
    """Trial processes; 0 = every core."""

    def __post_init__(self):
        _require(self.spheres_per_object >= 1, "simulate", "spheres_per_object", "must be >= 1")
        _require(self.baseline_trials >= -1, "simulate", "baseline_trials", "must be -1, 0 or a count")
        _require(self.mu >= 0, "simulate", "mu", "must be >= 0")
        _require(self.cone_edges >= 3, "simulate", "cone_edges", "must be >= 3")
        _require(self.torsional_friction_m >= 0, "simulate", "torsional_friction_m", "must be >= 0")
        for key in (
            "contact_tolerance_m",
            "retract_step_m",
            "retract_max_m",
            "approach_step_m",
            "near_m",
            "link_point_spacing_m",
            "contact_point_spacing_m",
            "coplanar_deg",
        ):
            _require(getattr(self, key) > 0, "simulate", key, "must be > 0")
        _require(
            self.approach_step_m <= self.contact_tolerance_m,
            "simulate",
            "approach_step_m",
            "must be at most contact_tolerance_m (a step must not jump past a touch)",
        )
        _require(self.near_m >= self.contact_tolerance_m, "simulate", "near_m", "must be at least contact_tolerance_m")
        _require(
            self.approach_max_m == -1 or self.approach_max_m >= 0,
            "simulate",
            "approach_max_m",
            "must be -1 (the hand's max_graspable_diameter) or >= 0",
        )
        _require(
            self.contact_point_spacing_m <= self.link_point_spacing_m,
            "simulate",
            "contact_point_spacing_m",
            "must be at most link_point_spacing_m",
        )
        _require(self.max_close_steps >= 1, "simulate", "max_close_steps", "must be >= 1")
        _require(
            self.max_link_contacts == 0 or self.max_link_contacts >= 2,
            "simulate",
            "max_link_contacts",
            "must be 0 (every corner) or >= 2",
        )
        _require(self.grid_cells >= 8, "simulate", "grid_cells", "must be >= 8")
        for key in ("approach_to_contact", "palm_contacts"):
            _require(isinstance(getattr(self, key), bool), "simulate", key, "must be true or false")
        _require(self.workers >= 0, "simulate", "workers", "must be >= 0")


@dataclass(frozen=True)
class CheckParams:
    """How well the analytic score predicts holding (stages ``decompose`` and ``check``, issue
    15): a seeded sample of each run's trials gets the pybullet lift-and-shake check
    (:mod:`pipeline.checks.physics`) and robust force closure (:mod:`pipeline.checks.robust`)."""

    trials: int = 25
    """Trials checked per run (object, scale, hand) and planner, a seeded sample; -1 = every
    trial, 0 = none (the checks table is empty)."""
    physics: bool = True
    """The lift-and-shake check (``physics_*``, ``mujoco_*`` columns); false: they are empty."""
    engine: str = "both"
    """Which lift-and-shake: ``pybullet`` (:mod:`pipeline.checks.physics`: ``physics_*`` columns),
    ``mujoco`` (:mod:`pipeline.checks.mujoco_check`: ``mujoco_*`` from the closed pose and
    ``mujoco_open_*`` from the open hand) or ``both``."""
    payload_kg: float = 0.1
    """The graspable-mass rule: the checked object weighs its mesh volume times
    ``density_kg_m3``, at most this (DexGraspBench's and DexGraspNet 2's 0.1 kg payload), so a
    heavy object is not a failed grasp; -1 = no cap."""
    torsional_friction_m: float = 0.005
    """MuJoCo's torsional friction (m: the radius of the contact patch that resists a turn
    about the normal; pybullet's check has none)."""
    close_s: float = 0.5
    """MuJoCo's open start: time the open hand's servos close on the free object (no gravity)."""
    robust_samples: int = 16
    """Perturbed copies per checked trial for ``robust_fc`` and ``robust_epsilon``; 0 = none."""
    pose_sigma_m: float = 0.005
    """Robust force closure: standard deviation of the grasp point's error per axis."""
    angle_sigma_rad: float = 0.05
    """... of the hand orientation's error (rotation vector, per axis)."""
    mu_sigma: float = 0.1
    """... of the friction coefficient (about ``simulate.mu``, at least 0)."""
    density_kg_m3: float = 500.0
    """The object's density: its mass is the mesh volume times this (500: a wooden or hollow
    plastic part; a 4 cm cube weighs 32 g)."""
    vhacd_resolution: int = 1000000
    """Voxels of pybullet's V-HACD convex decomposition (the dynamic object's shape)."""
    open_back: float = 0.002
    """The check starts from the trial's closed joints opened by this (rad or m per joint)..."""
    squeeze: float = 0.5
    """... and drives them toward the closed joints closed further by this (clipped at the
    limits), far enough that a touching joint pushes at the hand's ``joint_effort``."""
    settle_damping: float = 0.9
    """Bullet's linear and angular damping of the object (under gravity) while the fingers
    squeeze: it settles where their forces and its weight balance, or slides out."""
    settle_s: float = 0.25
    """Time the fingers squeeze the damped object before the lift."""
    lift_s: float = 0.5
    """Time undamped under gravity after the settle (a 10 cm lift at 0.2 m/s)."""
    shake_g: float = 1.0
    """Each shake: a force of this many times the object's weight along +-x, +-y, +-z ..."""
    shake_s: float = 0.2
    """... for this long each."""
    slip_m: float = 0.02
    """Held: the object moved at most this far relative to the hand (centre of mass) ..."""
    slip_rad: float = 0.35
    """... and turned at most this much (20 degrees), still touching the hand."""

    def __post_init__(self):
        _require(self.trials >= -1, "checks", "trials", "must be -1 (every trial), 0 (none) or a count")
        _require(self.robust_samples >= 0, "checks", "robust_samples", "must be >= 0")
        for key in (
            "pose_sigma_m",
            "angle_sigma_rad",
            "mu_sigma",
            "open_back",
            "squeeze",
            "lift_s",
            "shake_g",
            "shake_s",
        ):
            _require(getattr(self, key) >= 0, "checks", key, "must be >= 0")
        _require(0 <= self.settle_damping < 1, "checks", "settle_damping", "must be in [0, 1)")
        for key in ("density_kg_m3", "settle_s", "slip_m", "slip_rad"):
            _require(getattr(self, key) > 0, "checks", key, "must be > 0")
        _require(self.vhacd_resolution >= 10000, "checks", "vhacd_resolution", "must be >= 10000")
        _require(self.engine in ENGINES, "checks", "engine", f"must be one of {', '.join(ENGINES)}")
        _require(self.payload_kg == -1 or self.payload_kg > 0, "checks", "payload_kg", "must be > 0 or -1 (no cap)")
        for key in ("torsional_friction_m", "close_s"):
            _require(getattr(self, key) >= 0, "checks", key, "must be >= 0")

    def physics_settings(self, mu):
        """Keyword arguments of :class:`pipeline.checks.physics.PhysicsSettings` (friction ``mu``)."""
        names = (
            "density_kg_m3",
            "open_back",
            "squeeze",
            "settle_damping",
            "settle_s",
            "lift_s",
            "shake_g",
            "shake_s",
            "slip_m",
            "slip_rad",
            "payload_kg",
        )
        return {"mu": mu, **{name: getattr(self, name) for name in names}}


@dataclass(frozen=True)
class ReportParams:
    """The report (stage ``report``): tables, metrics, plots and figures."""

    figure_objects: list = field(default_factory=lambda: ["mug", "kettle", "giraffe"])
    """Objects drawn as figures (medial spheres, candidates, example grasps), at every scale."""
    example_grasps: int = 3
    """Force-closure grasps with the highest epsilon drawn per object, scale and hand."""
    epsilon_bins: int = 20
    """Bins of the epsilon histograms (``report/plots/epsilon.csv``)."""

    def __post_init__(self):
        _require(
            all(isinstance(name, str) for name in self.figure_objects),
            "report",
            "figure_objects",
            "must list object names",
        )
        _require(self.example_grasps >= 0, "report", "example_grasps", "must be >= 0")
        _require(self.epsilon_bins >= 2, "report", "epsilon_bins", "must be >= 2")


@dataclass(frozen=True)
class Params:
    """Every section of ``params.yaml``."""

    seed: int = 0
    objects: dict = field(default_factory=dict)
    scales: tuple = (1.0,)
    """Sizes each object runs at, as factors of its own (Table I: 1.0 and 0.5); kept as written,
    since ``data/<object>/<scale>/`` is named by DVC from the same text."""
    record: bool = True
    """Write the rerun recordings of classify and simulate (``logs/**/*.rrd``); off: the .rrd
    files are written empty. The MCAP logs are always written."""
    sample: SampleParams = field(default_factory=SampleParams)
    medial_axis: MedialAxisParams = field(default_factory=MedialAxisParams)
    mat: MatParams = field(default_factory=MatParams)
    sphere_grid: SphereGridParams = field(default_factory=SphereGridParams)
    classify: ClassifyParams = field(default_factory=ClassifyParams)
    concavity: ConcavityParams = field(default_factory=ConcavityParams)
    candidates: CandidatesParams = field(default_factory=CandidatesParams)
    simulate: SimulateParams = field(default_factory=SimulateParams)
    checks: CheckParams = field(default_factory=CheckParams)
    report: ReportParams = field(default_factory=ReportParams)


SECTIONS = {f.name: f.type for f in dataclasses.fields(Params) if dataclasses.is_dataclass(f.type)}


def _require(condition, section, key, problem):
    if not condition:
        raise BadParamsError(f"params: {section}.{key} {problem}")


def section_from_mapping(cls, mapping, *, section, source="params"):
    """Build the dataclass ``cls`` from a mapping holding every one of its keys, rejecting
    missing and unknown keys and bad types."""
    if not isinstance(mapping, dict):
        raise BadParamsError(f"{source}: section '{section}' must be a mapping, got {type(mapping).__name__}")
    known = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(mapping) - set(known))
    if unknown:
        raise BadParamsError(f"{source}: {section}: unknown key {unknown[0]!r} (known: {', '.join(known)})")
    missing = [key for key in known if key not in mapping]
    if missing:
        raise BadParamsError(
            f"{source}: {section}: missing key {missing[0]!r} (`python -m pipeline.params` prints a complete file)"
        )
    values = {}
    for key, value in mapping.items():
        expected = known[key].type
        if expected is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if expected in (int, float, str, bool, list) and (type(value) is not expected):
            raise BadParamsError(f"{source}: {section}.{key} must be {expected.__name__}, got {value!r}")
        if expected is float and not math.isfinite(value):
            raise BadParamsError(f"{source}: {section}.{key} must be finite, got {value!r}")
        values[key] = value
    try:
        return cls(**values)
    except BadParamsError as err:
        raise BadParamsError(f"{source}: {str(err).removeprefix('params: ')}") from None


def defaults():
    """Every section and key of a params file with its default value (a dict for YAML); no
    objects."""
    params = Params()
    return {
        "seed": params.seed,
        "objects": {},
        "record": params.record,
        "scales": list(params.scales),
        **{name: dataclasses.asdict(getattr(params, name)) for name in SECTIONS},
    }


def read_mapping(path):
    """The params file at ``path`` as a dict of sections, unvalidated (one-line errors for a
    missing file, bad YAML or a file that is not a mapping)."""
    try:
        raw = yaml.safe_load(Path(path).read_text())
    except FileNotFoundError:
        raise BadParamsError(f"{path}: file not found") from None
    except yaml.YAMLError as err:
        problem = str(err).replace("\n", " ")
        raise BadParamsError(f"{path}: not valid YAML ({problem})") from None
    if not isinstance(raw, dict):
        raise BadParamsError(f"{path}: must be a mapping of sections")
    return raw


def parse_scales(scales, *, source):
    """``scales`` of a params file as a tuple of floats: a list of distinct positive numbers."""
    if not (
        isinstance(scales, list)
        and scales
        and all(
            isinstance(scale, (int, float)) and not isinstance(scale, bool) and math.isfinite(scale) and scale > 0
            for scale in scales
        )
        and len(set(scales)) == len(scales)
    ):
        raise BadParamsError(f"{source}: scales must be a list of distinct positive numbers, got {scales!r}")
    return tuple(scales)


def load_params(path="params.yaml"):
    """Read and validate the whole params file.

    Returns
    -------
    Params
    """
    path = Path(path)
    raw = read_mapping(path)
    unknown = sorted(set(raw) - {f.name for f in dataclasses.fields(Params)})
    if unknown:
        raise BadParamsError(f"{path}: unknown section {unknown[0]!r}")
    missing = [f.name for f in dataclasses.fields(Params) if f.name not in raw]
    if missing:
        raise BadParamsError(
            f"{path}: missing section {missing[0]!r} (`python -m pipeline.params` prints a complete file)"
        )
    seed = raw["seed"]
    if type(seed) is not int or seed < 0:
        raise BadParamsError(f"{path}: seed must be a non-negative int, got {seed!r}")
    objects = raw["objects"] or {}
    if not isinstance(objects, dict):
        raise BadParamsError(f"{path}: objects must be a mapping name -> spec")
    scales = parse_scales(raw["scales"], source=path)
    record = raw["record"]
    if type(record) is not bool:
        raise BadParamsError(f"{path}: record must be true or false, got {record!r}")
    sections = {
        name: section_from_mapping(cls, raw[name], section=name, source=str(path)) for name, cls in SECTIONS.items()
    }
    strangers = [name for name in sections["report"].figure_objects if objects and name not in objects]
    if strangers:
        raise BadParamsError(f"{path}: report.figure_objects names {strangers[0]!r}, which is not under objects")
    return Params(seed=seed, objects=objects, scales=scales, record=record, **sections)


if __name__ == "__main__":
    print(yaml.safe_dump(defaults(), sort_keys=False), end="")

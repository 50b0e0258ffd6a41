"""Replay an exported file through the trial engine from the file alone."""

from types import SimpleNamespace

from .export_files import read_grasps


def replay_file(path, *, hand=None, settings=None):
    """Replay every grasp of an exported file through the trial engine from the file alone: its
    mesh, poses and joints (:meth:`pipeline.trial.engine.GraspEngine.replay`).

    Parameters
    ----------
    hand : Hand, optional
        Default: the built-in hand the file names.
    settings : SimulateParams, optional
        The run's ``simulate`` params (their defaults when None).

    Returns
    -------
    found : dict (:func:`pipeline.outputs.export_files.read_grasps`), results : list of TrialResult in the file's order
    """

    from ..hands.spec import get_hand
    from ..trial.engine import GraspEngine

    found = read_grasps(path)
    mesh = SimpleNamespace(vertices=found["vertices"], faces=found["faces"])
    engine = GraspEngine(mesh, hand or get_hand(found["hand"]), settings)
    return found, engine.replay(found["transforms"], found["joints"])

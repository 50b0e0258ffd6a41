"""Robot hands: the limits the planner needs, declared in one place per hand.

Today a hand declares its largest graspable sphere diameter (paper IV: ARMAR-III 9.4 cm,
Barrett 14 cm; a parallel jaw its stroke) and its preshapes. The simulation issue adds
kinematics, URDFs and user hands.
"""

from dataclasses import dataclass

from .errors import BadParamsError


@dataclass(frozen=True)
class Hand:
    """A hand's planning limits.

    Attributes
    ----------
    name : str
    max_graspable_diameter : float, metres
    preshapes : tuple of str, the first is the default
    """

    name: str
    max_graspable_diameter: float
    preshapes: tuple = ("parallel",)


HANDS = {
    "armar3": Hand("armar3", 0.094, ("parallel", "power", "precision")),
    "barrett": Hand("barrett", 0.14, ("parallel",)),
    "parallel_jaw": Hand("parallel_jaw", 0.08, ("parallel",)),
}


def get_hand(name):
    """The built-in hand called ``name``; an unknown name is a one-line error."""
    if name not in HANDS:
        raise BadParamsError(f"unknown hand {name!r} (built-in: {', '.join(HANDS)})")
    return HANDS[name]

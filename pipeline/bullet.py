"""pybullet, imported without the build-time banner its C extension prints on stderr (which
would break the one-line error contract of every command)."""

import os
import sys


def _import_quietly():
    sys.stderr.flush()
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    try:
        import pybullet
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
    return pybullet


pybullet = _import_quietly()


def load_hand(hand, client):
    """Load ``hand``'s URDF (its file, the subtree from its ``base_link``, or a built-in's
    generated text) as a fixed-base body."""
    import tempfile

    from .hands import urdf_text

    if hand.urdf is not None and hand.base_link is None:
        return pybullet.loadURDF(hand.urdf, useFixedBase=True, physicsClientId=client)
    if hand.urdf is not None:  # a hand that is part of a larger robot: its subtree alone
        from .urdf import subtree_text

        text = subtree_text(hand.urdf, hand.base_link)
    else:
        text = urdf_text(hand)
    descriptor, path = tempfile.mkstemp(suffix=".urdf")
    try:
        with os.fdopen(descriptor, "w") as stream:
            stream.write(text)
        return pybullet.loadURDF(path, useFixedBase=True, physicsClientId=client)
    finally:
        os.unlink(path)


class BulletClient:
    """A headless pybullet client of its own (``DIRECT``): ``_call`` passes its id to a pybullet
    function, :meth:`close` disconnects it (once)."""

    def __init__(self):
        self.client = pybullet.connect(pybullet.DIRECT)

    def _call(self, function, *args, **kwargs):
        return function(*args, physicsClientId=self.client, **kwargs)

    def close(self):
        if self.client is not None:
            pybullet.disconnect(physicsClientId=self.client)
            self.client = None

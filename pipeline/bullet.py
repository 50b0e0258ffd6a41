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


def load_hand_body(hand, client):
    """Load ``hand``'s URDF (:func:`pipeline.hands.spec.hand_urdf_text`: rooted at its base
    frame) as a fixed-base body."""
    import tempfile

    from .hands.spec import hand_urdf_text

    descriptor, path = tempfile.mkstemp(suffix=".urdf")
    try:
        with os.fdopen(descriptor, "w") as stream:
            stream.write(hand_urdf_text(hand))
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

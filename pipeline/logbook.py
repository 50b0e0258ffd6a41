"""MCAP logs of stage runs: typed JSON messages (one JSON schema per topic) that the ``mcap``
tooling, Foxglove or pandas read back (README, "Logs").

Topics: ``/stage`` (start, end), ``/params``, ``/artefacts`` (path and SHA-256 of each input
and output), ``/counts``, ``/timing``, ``/warning``, ``/modules`` (the ``pipeline`` modules
loaded) and ``/trials`` (one message per trial).
Every message is stamped with the wall clock (ns).
"""

import contextlib
import hashlib
import json
import time

from .artefacts import atomic_path, json_ready

_NUMBER = {"type": "number"}
SCHEMAS = {
    "/stage": {
        "type": "object",
        "properties": {"stage": {"type": "string"}, "event": {"type": "string", "enum": ["start", "end"]}},
    },
    "/params": {"type": "object", "description": "the params the stage used"},
    "/artefacts": {
        "type": "object",
        "properties": {
            "role": {"type": "string", "enum": ["input", "output"]},
            "path": {"type": "string"},
            "sha256": {"type": "string"},
            "bytes": {"type": "integer"},
        },
    },
    "/counts": {"type": "object", "description": "sizes of what the stage made"},
    "/timing": {
        "type": "object",
        "properties": {
            "stage": {"type": "string"},
            "seconds": _NUMBER,
            "process_seconds": _NUMBER,
            "record_seconds": _NUMBER,
        },
    },
    "/warning": {"type": "object", "properties": {"message": {"type": "string"}}},
    "/modules": {
        "type": "object",
        "properties": {"modules": {"type": "array", "items": {"type": "string"}}},
        "description": "the pipeline modules the stage loaded",
    },
    "/trials": {
        "type": "object",
        "description": "one grasp trial: every column of trials.parquet",
        "properties": {
            "hand": {"type": "string"},
            "planner": {"type": "string"},
            "outcome": {"type": "string"},
            "epsilon": _NUMBER,
        },
    },
}


class McapLog:
    """Writer of JSON messages on the :data:`SCHEMAS` topics; a channel is registered on first use."""

    def __init__(self, writer):
        self.writer, self.channels = writer, {}

    def log(self, topic, message):
        """Write ``message`` (a JSON-able dict; numpy values allowed) on ``topic``."""
        if topic not in self.channels:
            schema = self.writer.register_schema(
                name=topic.strip("/"), encoding="jsonschema", data=json.dumps(SCHEMAS[topic]).encode()
            )
            self.channels[topic] = self.writer.register_channel(topic=topic, message_encoding="json", schema_id=schema)
        now = time.time_ns()
        self.writer.add_message(
            self.channels[topic],
            log_time=now,
            publish_time=now,
            data=json.dumps(json_ready(message), default=str, allow_nan=False).encode(),
        )

    def artefact(self, role, path):
        """An ``/artefacts`` message: ``role`` ("input" or "output"), the path, its size and SHA-256."""
        digest, size = file_digest(path)
        self.log("/artefacts", {"role": role, "path": str(path), "sha256": digest, "bytes": size})

    def trials(self, trials):
        """One ``/trials`` message per row of a trials table, every column (joints as a list)."""
        for row in trials.to_dict(orient="records"):
            self.log("/trials", row)


def file_digest(path):
    """(SHA-256 hex, size in bytes) of a file."""
    digest, size = hashlib.sha256(), 0
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
            size += len(block)
    return digest.hexdigest(), size


@contextlib.contextmanager
def mcap_log(path, stage):
    """An :class:`McapLog` writing to ``path`` (.mcap), opened by a ``/stage`` start message and
    closed by an end message; renamed into place only when the block succeeds."""
    from mcap.writer import Writer

    with atomic_path(path) as tmp, open(tmp, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile="", library="medial-grasp")
        log = McapLog(writer)
        log.log("/stage", {"stage": stage, "event": "start"})
        yield log
        log.log("/stage", {"stage": stage, "event": "end"})
        writer.finish()


def read_log(path):
    """Every message of an MCAP log as ``[(topic, message dict)]``, in log order."""
    from mcap.reader import make_reader

    with open(path, "rb") as stream:
        return [
            (channel.topic, json.loads(message.data))
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=True)
        ]

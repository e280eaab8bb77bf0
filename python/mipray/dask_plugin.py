"""The Dask worker plugin of :mod:`mipray.distributed`: a render session per stage.

Its own module because a worker plugin must subclass ``distributed.WorkerPlugin``:
importing it imports Dask, which ``import mipray`` does not.
"""

from __future__ import annotations

from typing import Any, Protocol

from distributed import WorkerPlugin, get_worker

from .distributed import PLUGIN_NAME
from .session import RenderSession, open_stage

__all__ = ["SessionPlugin", "worker_plugin"]


class StageJob(Protocol):
    """What a session is opened from (:class:`mipray.distributed.Job`)."""

    @property
    def stage_path(self) -> str: ...
    @property
    def mask(self) -> tuple[str, ...] | None: ...
    @property
    def session_layer(self) -> str | None: ...
    @property
    def purposes(self) -> tuple[str, ...] | None: ...
    def session_key(self) -> tuple[Any, ...]: ...


class SessionPlugin(WorkerPlugin):
    """A Dask worker plugin holding one :class:`RenderSession` per stage on its worker.

    Registered by :func:`mipray.distributed.connect` (``Client.register_plugin``), so every worker,
    including one that joins or is restarted later, gets one. A session is
    opened by the first piece of its stage on the worker and kept for the
    worker's life.
    """

    name = PLUGIN_NAME

    def __init__(self) -> None:
        self.sessions: dict[tuple[Any, ...], RenderSession] = {}
        # Per session: its scene delegate's sync counts when a piece last reported them, and
        # whether no piece has reported its opening yet, so each piece reports what was synced
        # since the last (the view resolved before the first piece included).
        self.reported: dict[tuple[Any, ...], dict[str, int]] = {}
        self.unreported_open: set[tuple[Any, ...]] = set()

    def setup(self, worker: Any) -> None:
        """Dask's hook on a worker's start: no session yet."""
        self.sessions = {}
        self.reported = {}
        self.unreported_open = set()

    def teardown(self, worker: Any) -> None:
        """Dask's hook on a worker's close: stop the sessions following their stages."""
        for session in self.sessions.values():
            session.close()
        self.sessions.clear()

    def session(self, job: StageJob) -> tuple[RenderSession, bool]:
        """The worker's session for ``job``'s stage, and whether it was opened just now."""
        key = job.session_key()
        if key in self.sessions:
            return self.sessions[key], False
        stage = open_stage(
            job.stage_path, population_mask=job.mask, session_layer=job.session_layer
        )
        session = RenderSession(stage, purposes=job.purposes)
        self.sessions[key] = session
        self.reported[key] = {}
        self.unreported_open.add(key)
        return session, True

    def report(self, job: StageJob) -> tuple[list[str], bool]:
        """The prims sent to ``job``'s session since the last report, and whether it opened."""
        key = job.session_key()
        counts = self.sessions[key].scene.sync_counts
        last = self.reported.get(key, {})
        synced = sorted(p for p, n in counts.items() if n != last.get(p, 0))
        self.reported[key] = dict(counts)
        opened = key in self.unreported_open
        self.unreported_open.discard(key)
        return synced, opened


def worker_plugin() -> SessionPlugin:
    """The plugin of the worker running this task (:func:`mipray.distributed.connect` registers it).

    A worker of a client that did not register it gets one here.
    """
    worker = get_worker()
    plugin = worker.plugins.get(PLUGIN_NAME)
    if not isinstance(plugin, SessionPlugin):
        plugin = SessionPlugin()
        plugin.setup(worker)
        worker.plugins[PLUGIN_NAME] = plugin
    return plugin
